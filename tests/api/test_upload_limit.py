"""Request bodies over ``max_upload_bytes`` get a 413 problem: at once when Content-Length says
so (before routing), or as soon as a chunked body has passed the limit, never read further."""

from __future__ import annotations

import asyncio

import httpx
import pytest
from fastapi import FastAPI, Request, UploadFile
from fastapi.responses import JSONResponse

from service.config import Settings
from service.main import create_app
from tests.api.helpers import assert_problem

LIMIT = 1000


def add_upload_routes(app: FastAPI) -> None:
    @app.post("/_test/upload")
    async def count_upload(request: Request):
        size = 0
        async for chunk in request.stream():
            size += len(chunk)
        return {"bytes": size}

    @app.post("/_test/form")
    async def count_form(file: UploadFile):
        return {"bytes": len(await file.read())}

    @app.post("/_test/swallow")
    async def swallow_errors(request: Request):
        try:
            await request.body()
        except Exception:
            return JSONResponse({"ok": True})
        return {"ok": True}


@pytest.fixture
def small_client(make_client):
    return make_client(Settings(max_upload_bytes=LIMIT), setup=add_upload_routes)


def chunks(total: int, size: int = 100):
    for start in range(0, total, size):
        yield b"x" * min(size, total - start)


def test_body_under_the_limit_passes(small_client):
    response = small_client.post("/_test/upload", content=b"x" * LIMIT)
    assert response.status_code == 200
    assert response.json() == {"bytes": LIMIT}
    chunked = small_client.post("/_test/upload", content=chunks(LIMIT))
    assert chunked.json() == {"bytes": LIMIT}


def test_content_length_over_the_limit_is_413_before_routing(small_client):
    for path in ("/_test/upload", "/no/such/route", "/healthz"):
        response = small_client.post(path, content=b"x" * (LIMIT + 1))
        body = assert_problem(response, 413, "too-large")
        assert body["limit"] == LIMIT
        assert response.headers["connection"] == "close"


def test_chunked_body_over_the_limit_is_413(small_client):
    response = small_client.post("/_test/upload", content=chunks(LIMIT + 1))
    assert "content-length" not in response.request.headers
    assert_problem(response, 413, "too-large")


def test_multipart_over_the_limit_is_413_not_a_parse_error(small_client):
    files = {"file": ("clip.bvh", b"x" * (2 * LIMIT), "text/plain")}
    assert_problem(small_client.post("/_test/form", files=files), 413, "too-large")

    # the same body streamed without Content-Length, through FastAPI's form parsing
    request = httpx.Request("POST", "http://test/_test/form", files=files)
    body = request.read()
    response = small_client.post(
        "/_test/form",
        content=iter([body[:500], body[500:]]),
        headers={"content-type": request.headers["content-type"]},
    )
    assert_problem(response, 413, "too-large")


def test_swallowed_limit_error_still_answers_413(small_client):
    assert_problem(small_client.post("/_test/swallow", content=chunks(3 * LIMIT)), 413)


def test_reading_stops_once_over_the_limit():
    """At the ASGI level: a 100 x 100-byte upload with a 1000-byte limit is read no further
    than the chunk that passes the limit."""
    app = create_app(Settings(max_upload_bytes=LIMIT))
    add_upload_routes(app)
    received = 0
    sent: list[dict] = []

    async def receive():
        nonlocal received
        received += 1
        return {"type": "http.request", "body": b"x" * 100, "more_body": received < 100}

    async def send(message):
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": "/_test/upload",
        "raw_path": b"/_test/upload",
        "query_string": b"",
        "root_path": "",
        "headers": [(b"transfer-encoding", b"chunked")],
        "client": ("127.0.0.1", 1234),
        "server": ("test", 80),
    }
    asyncio.run(app(scope, receive, send))
    assert received == LIMIT // 100 + 1
    start = next(m for m in sent if m["type"] == "http.response.start")
    assert start["status"] == 413
    assert (b"content-type", b"application/problem+json") in start["headers"]

"""Error answers that must not turn into 500s: odd extension members (numpy values, NaN,
bytes), query strings that are not UTF-8, and errors raised while the body streams."""

from __future__ import annotations

import asyncio
import json

import numpy as np
from fastapi import FastAPI

from motion.errors import MotionError
from service.config import Settings
from service.errors import NotFound, PayloadTooLarge
from service.main import create_app
from tests.api.helpers import assert_problem


def add_odd_routes(app: FastAPI) -> None:
    @app.get("/_test/numpy-limit")
    async def numpy_limit():
        raise PayloadTooLarge("too many", limit=np.int64(20000), seconds=np.float32(1.5))

    @app.get("/_test/nan-limit")
    async def nan_limit():
        raise MotionError("odd", kind="too-large", limit=float("nan"))

    @app.get("/_test/odd-members")
    async def odd_members():
        raise NotFound("odd", names=np.array(["a", "b"]), raw=b"\xff", nested={"x": np.inf})


def test_odd_extension_members_still_make_a_problem(make_client):
    client = make_client(setup=add_odd_routes)
    body = assert_problem(client.get("/_test/numpy-limit"), 413, "too-large")
    assert body["limit"] == 20000 and body["seconds"] == 1.5
    body = assert_problem(client.get("/_test/nan-limit"), 413, "too-large")
    assert body["limit"] == "nan"
    body = assert_problem(client.get("/_test/odd-members"), 404, "not-found")
    assert body["names"] == ["a", "b"] and body["nested"] == {"x": "inf"}
    assert isinstance(body["raw"], str)


def asgi_get(app, path: str, query: bytes) -> tuple[int, dict, bytes]:
    scope = {
        "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET",
        "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": query,
        "root_path": "", "headers": [], "client": ("127.0.0.1", 1), "server": ("t", 80),
    }  # fmt: skip
    sent: list[dict] = []

    async def receive():
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message):
        sent.append(message)

    asyncio.run(app(scope, receive, send))
    start = next(m for m in sent if m["type"] == "http.response.start")
    body = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    return start["status"], dict(start["headers"]), body


def test_a_query_string_that_is_not_utf8_is_not_a_500():
    app = create_app(Settings())
    for path, status in (("/v1/nope", 404), ("/healthz", 200), ("/openapi.json", 200)):
        code, headers, body = asgi_get(app, path, b"a=\xff\xfe&format=%ff")
        assert code == status, body
        if code >= 400:
            assert headers[b"content-type"] == b"application/problem+json"
            assert json.loads(body)["status"] == status

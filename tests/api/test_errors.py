"""Every error is RFC 9457 problem+json: framework errors, MotionError kinds, service errors,
request validation, and unexpected exceptions (500 without a traceback)."""

from __future__ import annotations

import logging

import pytest
from fastapi import FastAPI

from motion.errors import MotionError
from service.errors import (
    CATALOGUE,
    InvalidRequest,
    NotFound,
    NotReady,
    Overloaded,
    PayloadTooLarge,
    ServiceError,
    Timeout,
    UnsupportedMediaType,
)
from tests.api.helpers import assert_problem

SERVICE_ERRORS = {
    "not-found": NotFound("no style named 'grumpy'", styles=["happy"]),
    "too-large": PayloadTooLarge("clip has 30001 frames", limit=20000),
    "unsupported-media-type": UnsupportedMediaType("audio/x-foo is not read"),
    "not-ready": NotReady("models are loading"),
    "timeout": Timeout("took too long", limit=60),
    "invalid-request": InvalidRequest("'mapping' is not JSON", field="mapping"),
    "overloaded": Overloaded("no slot", headers={"Retry-After": "5"}),
}


def add_error_routes(app: FastAPI) -> None:
    @app.get("/_test/motion/{kind}")
    async def raise_motion_error(kind: str):
        raise MotionError("line 3: bad channel", kind=kind, line=3, unmapped=["Tail"], limit=5)

    @app.get("/_test/service/{name}")
    async def raise_service_error(name: str):
        raise SERVICE_ERRORS[name]

    @app.get("/_test/items/{number}")
    async def read_item(number: int, size: int):
        return {"number": number, "size": size}

    @app.get("/_test/crash")
    async def crash():
        raise RuntimeError("secret internal detail")

    @app.get("/_test/crash-sync")
    def crash_sync():
        raise KeyError("secret internal detail")


@pytest.fixture
def error_client(make_client):
    return make_client(setup=add_error_routes)


def test_unknown_path_is_404_problem(client):
    body = assert_problem(client.get("/no/such/thing"), 404, "not-found")
    assert body["instance"] == "/no/such/thing"
    assert body["title"] == "Not found"


def test_wrong_method_is_405_problem_with_allow(client):
    response = client.post("/healthz")
    body = assert_problem(response, 405, "method-not-allowed")
    assert "GET" in response.headers["allow"]
    assert "POST" in body["detail"]


@pytest.mark.parametrize(
    ("kind", "status", "slug"),
    [
        ("invalid", 400, "invalid-input"),
        ("unusable", 422, "unusable-input"),
        ("too-large", 413, "too-large"),
        ("unsupported", 415, "unsupported-media-type"),
    ],
)
def test_motion_errors_map_by_kind(error_client, kind, status, slug):
    body = assert_problem(error_client.get(f"/_test/motion/{kind}"), status, slug)
    assert body["detail"] == "line 3: bad channel"
    assert body["line"] == 3
    assert body["unmapped"] == ["Tail"]
    assert body["limit"] == 5


@pytest.mark.parametrize(
    ("name", "status"),
    [
        ("not-found", 404),
        ("too-large", 413),
        ("unsupported-media-type", 415),
        ("not-ready", 503),
        ("timeout", 504),
        ("invalid-request", 400),
        ("overloaded", 503),
    ],
)
def test_service_errors_are_problems(error_client, name, status):
    exc = SERVICE_ERRORS[name]
    response = error_client.get(f"/_test/service/{name}")
    body = assert_problem(response, status, name)
    assert body["title"] == exc.title == CATALOGUE[name].title
    assert body["detail"] == exc.detail
    for key, value in exc.ext.items():
        assert body[key] == value
    for key, value in exc.headers.items():
        assert response.headers[key] == value


def test_every_service_error_class_names_a_catalogue_entry():
    classes, stack = set(), [ServiceError]
    while stack:
        cls = stack.pop()
        classes.add(cls)
        stack.extend(cls.__subclasses__())
    assert {cls.slug for cls in classes} <= set(CATALOGUE)
    slugs = [cls.slug for cls in classes if cls is not ServiceError]
    assert len(slugs) == len(set(slugs)), "two classes for one problem type"


def test_validation_error_is_400_with_field_errors(error_client):
    body = assert_problem(error_client.get("/_test/items/abc"), 400, "invalid-request")
    locations = {tuple(e["loc"]) for e in body["errors"]}
    assert ("path", "number") in locations
    assert ("query", "size") in locations
    assert all(set(e) == {"loc", "msg", "type"} for e in body["errors"])


@pytest.mark.parametrize("path", ["/_test/crash", "/_test/crash-sync"])
def test_unexpected_error_is_500_without_traceback_and_logged(error_client, caplog, path):
    with caplog.at_level(logging.ERROR, logger="service"):
        response = error_client.get(path, headers={"X-Request-Id": "crash-1"})
    body = assert_problem(response, 500, "internal-error")
    assert "secret" not in response.text
    assert body["request_id"] == "crash-1"
    logged = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert logged and any(r.exc_info for r in logged)
    assert any("secret internal detail" in str(r.exc_info[1]) for r in logged if r.exc_info)


def test_openapi_documents_problems_not_fastapi_422(make_client):
    client = make_client(setup=add_error_routes)
    schema = client.get("/openapi.json").json()
    responses = schema["paths"]["/_test/items/{number}"]["get"]["responses"]
    assert "422" not in responses
    assert "application/problem+json" in responses["400"]["content"]
    assert (
        "application/problem+json"
        in schema["paths"]["/readyz"]["get"]["responses"]["503"]["content"]
    )


def test_openapi_documents_the_answer_headers(make_client):
    """A tools programmer reading /docs learns the headers a file answer carries: the
    warnings on every clip route, a dance's genre and tempo on the dance route only."""
    schema = make_client().get("/openapi.json").json()
    for path in ("/v1/transfer", "/v1/stylize", "/v1/dance"):
        headers = schema["paths"][path]["post"]["responses"]["200"]["headers"]
        assert {"X-Warnings", "X-Frames", "X-Model-Version"} <= set(headers), path
        assert ("X-Dance-Genre" in headers) == (path == "/v1/dance"), path

"""Problems as HTTP answers: every error becomes an RFC 9457 ``application/problem+json``
response here, from the catalogue of :mod:`service.errors`, and the OpenAPI schema documents
them. :func:`install` registers the handlers on the app (``service.main``); the middleware
and the routes use :func:`service_error_response` and :func:`problem_responses`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from http import HTTPStatus
from typing import Any

import numpy as np
from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import Scope

from motion.errors import MotionError
from service import metrics
from service.errors import (
    CATALOGUE,
    MOTION_KINDS,
    PROBLEM_BASE,
    PROBLEM_MEDIA_TYPE,
    ServiceError,
    problem_kind,
)

logger = logging.getLogger("service.errors")


class Problem(BaseModel):
    """The body of every error response (for the OpenAPI schema; extension members allowed)."""

    model_config = ConfigDict(extra="allow")

    type: str
    title: str
    status: int
    detail: str
    instance: str
    request_id: str | None = None


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for a route's OpenAPI: the given statuses as problem+json,
    described by the catalogue's titles for that status."""
    out: dict[int | str, dict[str, Any]] = {}
    for status in statuses:
        titles = [p.title for p in CATALOGUE.values() if p.status == status]
        out[status] = {
            "content": {PROBLEM_MEDIA_TYPE: {"schema": Problem.model_json_schema()}},
            "description": " or ".join(titles) or problem_kind(status)[1],
        }
    return out


class ReadRefused(StarletteHTTPException):
    """A :class:`ServiceError` raised while FastAPI reads a request body (by the upload
    limit's ``receive``). FastAPI turns any other exception raised there into a 400 "error
    parsing the body"; a Starlette ``HTTPException`` it lets through untouched, and
    :func:`install` answers it as the problem it carries."""

    def __init__(self, error: ServiceError) -> None:
        super().__init__(error.status_code, error.detail, error.headers)
        self.error = error


def request_id_of(scope: Scope) -> str | None:
    """The id the request-context middleware gave this request (None outside it)."""
    state = scope.get("state") or {}
    return state.get("request_id")


def json_safe(value: Any) -> Any:
    """``value`` as plain JSON: numpy scalars and arrays become Python numbers and lists,
    non-finite floats strings, bytes text, anything else unknown its ``str``. An extension
    member must never turn an error answer into a 500."""
    if isinstance(value, np.generic):
        value = value.item()
    elif isinstance(value, np.ndarray):
        value = value.tolist()
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, bytes | bytearray):
        return bytes(value).decode("utf-8", "replace")
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [json_safe(v) for v in value]
    try:
        encoded = jsonable_encoder(value)
    except Exception:
        return str(value)
    return str(value) if encoded is value else json_safe(encoded)


class ProblemResponse(JSONResponse):
    media_type = PROBLEM_MEDIA_TYPE


def problem_response(
    scope: Scope,
    *,
    status: int,
    slug: str,
    title: str,
    detail: str,
    headers: Mapping[str, str] | None = None,
    **ext: Any,
) -> ProblemResponse:
    """Build an RFC 9457 response for the request in ``scope`` (and count it by type)."""
    metrics.count_error(slug)
    body: dict[str, Any] = {
        "type": PROBLEM_BASE + slug,
        "title": title,
        "status": status,
        "detail": detail,
        "instance": scope.get("path", ""),
    }
    extensions = {str(k): json_safe(v) for k, v in ext.items() if v is not None}
    body.update({k: v for k, v in extensions.items() if k not in body})
    request_id = request_id_of(scope)
    if request_id is not None:  # the header is the request-context middleware's
        body["request_id"] = request_id
    return ProblemResponse(body, status_code=status, headers=dict(headers or {}))


def service_error_response(scope: Scope, exc: ServiceError) -> ProblemResponse:
    return problem_response(
        scope,
        status=exc.status_code,
        slug=exc.slug,
        title=exc.title,
        detail=exc.detail or exc.title,
        headers=exc.headers,
        **exc.ext,
    )


def internal_error_response(scope: Scope) -> ProblemResponse:
    """The 500 answer: no traceback, no exception text; the log has them."""
    problem = CATALOGUE["internal-error"]
    return problem_response(
        scope,
        status=problem.status,
        slug=problem.slug,
        title=problem.title,
        detail="The server failed to process the request; the error has been logged.",
    )


async def handle_service_error(request: Request, exc: Exception) -> ProblemResponse:
    assert isinstance(exc, ServiceError | ReadRefused)
    error = exc.error if isinstance(exc, ReadRefused) else exc
    return service_error_response(request.scope, error)


async def handle_motion_error(request: Request, exc: Exception) -> ProblemResponse:
    assert isinstance(exc, MotionError)
    problem = CATALOGUE[MOTION_KINDS.get(exc.kind, "invalid-input")]
    return problem_response(
        request.scope,
        status=problem.status,
        slug=problem.slug,
        title=problem.title,
        detail=exc.message,
        **exc.details(),
    )


async def handle_validation_error(request: Request, exc: Exception) -> ProblemResponse:
    assert isinstance(exc, RequestValidationError)
    errors = [
        {
            "loc": [str(part) for part in err.get("loc", ())],
            "msg": str(err.get("msg", "")),
            "type": str(err.get("type", "")),
        }
        for err in exc.errors()
    ]
    where = ", ".join(".".join(e["loc"]) + ": " + e["msg"] for e in errors[:3])
    more = f" (and {len(errors) - 3} more)" if len(errors) > 3 else ""
    problem = CATALOGUE["invalid-request"]
    return problem_response(
        request.scope,
        status=problem.status,
        slug=problem.slug,
        title=problem.title,
        detail=f"The request is malformed: {where}{more}" if where else "The request is malformed",
        errors=errors,
    )


async def handle_http_exception(request: Request, exc: Exception) -> ProblemResponse:
    """Framework HTTP errors: 404 unknown path, 405 wrong method, and any other status."""
    assert isinstance(exc, StarletteHTTPException)
    status = exc.status_code
    slug, title = problem_kind(status)
    # scope["path"], not request.url: building the URL decodes the query string as UTF-8,
    # and a client may send any bytes there
    method, path = request.method, request.scope.get("path", "")
    if status == 404 and exc.detail == HTTPStatus.NOT_FOUND.phrase:
        detail = f"No resource at {path}"
    elif status == 405 and exc.detail == HTTPStatus.METHOD_NOT_ALLOWED.phrase:
        allow = _allowed_methods(request) or (exc.headers or {}).get("Allow")
        if allow:  # Starlette's names the first route of the path only (GET, not POST)
            exc.headers = {**{k: v for k, v in (exc.headers or {}).items() if k.lower() != "allow"},
                           "Allow": allow}  # fmt: skip
        detail = f"{method} is not allowed on {path}" + (f"; allowed: {allow}" if allow else "")
    else:
        detail = str(exc.detail)
    return problem_response(
        request.scope, status=status, slug=slug, title=title, detail=detail, headers=exc.headers
    )


def _allowed_methods(request: Request) -> str:
    """The methods the OpenAPI schema documents at the request's path, as an ``Allow``
    value (empty when the path is not documented)."""
    from starlette.routing import compile_path

    path = request.scope.get("path", "")
    try:
        paths = request.app.openapi().get("paths", {})
    except Exception:  # a schema that cannot be built must not turn a 405 into a 500
        return ""
    methods = {
        method.upper()
        for template, operations in paths.items()
        if compile_path(template)[0].match(path)
        for method in operations
    }
    return ", ".join(sorted(methods))


async def handle_unexpected_error(request: Request, exc: Exception) -> ProblemResponse:
    """Last resort (Starlette's outermost error middleware); normally the request-context
    middleware has already answered and logged."""
    path = request.scope.get("path", "")
    logger.error("unhandled error in %s %s", request.method, path, exc_info=exc)
    return internal_error_response(request.scope)


def _document_problems(app: FastAPI) -> None:
    """Make the OpenAPI schema tell the truth: FastAPI documents request validation errors as
    422 ``HTTPValidationError``; this service answers them with a 400 problem."""
    build_schema = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema:
            return app.openapi_schema
        schema = build_schema()
        for path_item in schema.get("paths", {}).values():
            for operation in path_item.values():
                responses = operation.get("responses", {})
                default = responses.get("422", {})
                if "HTTPValidationError" in str(default.get("content", "")):
                    del responses["422"]
                    responses.setdefault("400", problem_responses(400)[400])
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def install(app: FastAPI) -> None:
    """Register every handler of this module on ``app`` (and document them in its OpenAPI)."""
    _document_problems(app)
    app.add_exception_handler(ServiceError, handle_service_error)
    app.add_exception_handler(ReadRefused, handle_service_error)
    app.add_exception_handler(MotionError, handle_motion_error)
    app.add_exception_handler(RequestValidationError, handle_validation_error)
    app.add_exception_handler(StarletteHTTPException, handle_http_exception)
    app.add_exception_handler(Exception, handle_unexpected_error)

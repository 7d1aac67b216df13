"""Error types of the service and their handlers, registered by :func:`install_error_handlers`.

Every error response is RFC 9457 ``application/problem+json``::

    {"type": "https://motion-style.example/problems/invalid-input",
     "title": "Invalid input", "status": 400,
     "detail": "line 12: expected 'ROOT'", "instance": "/v1/transfer",
     "line": 12, "request_id": "4f0c..."}

``type`` is always ``PROBLEM_BASE + slug`` (never ``about:blank``), one slug per kind of
problem, so clients can switch on it; ``title`` is fixed per type, ``detail`` says what
happened this time, ``instance`` is the request path. Extension members: ``request_id``
always; ``line`` (1-based line of a text file), ``unmapped`` (joint names), ``limit`` where
they apply; ``errors`` (field errors) for a malformed request.

:data:`CATALOGUE` lists every problem type (slug, status, title, what raises it) once; the
exception classes, the answers to the framework's own errors and the OpenAPI documentation
all read it. Library code raises :class:`motion.errors.MotionError` (its ``kind`` names a
slug of the catalogue); service code raises a :class:`ServiceError` subclass. Both become
problems here and nowhere else.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from http import HTTPStatus
from typing import Any, ClassVar

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

logger = logging.getLogger(__name__)

PROBLEM_BASE = "https://motion-style.example/problems/"
PROBLEM_MEDIA_TYPE = "application/problem+json"


@dataclass(frozen=True)
class ProblemType:
    slug: str
    status: int
    title: str
    raised_for: str


CATALOGUE: dict[str, ProblemType] = {
    p.slug: p
    for p in (
        ProblemType("invalid-request", 400, "Invalid request", "fields missing or malformed"),
        ProblemType("invalid-input", 400, "Invalid input", "a file we read but is malformed"),
        ProblemType(
            "unauthorized",
            401,
            "Unauthorized",
            "no API key, or one that is not known (or was revoked), where keys are required",
        ),
        ProblemType("forbidden", 403, "Forbidden", "an API key without the scope a route needs"),
        ProblemType("not-found", 404, "Not found", "unknown path, style or model"),
        ProblemType("method-not-allowed", 405, "Method not allowed", "wrong method for a path"),
        ProblemType(
            "conflict",
            409,
            "Conflict",
            "a style name taken, a shipped style deleted, the style store full, a style "
            "registered under another model version",
        ),
        ProblemType("too-large", 413, "Content too large", "upload, clip or audio over a limit"),
        ProblemType(
            "unsupported-media-type", 415, "Unsupported media type", "a format we do not read"
        ),
        ProblemType("unusable-input", 422, "Unusable input", "well-formed but unusable"),
        ProblemType(
            "too-many-requests",
            429,
            "Too many requests",
            "an API key over its request rate or its requests in progress (per replica)",
        ),
        ProblemType("internal-error", 500, "Internal server error", "a bug (logged, not shown)"),
        ProblemType("not-ready", 503, "Service not ready", "models not loaded (yet)"),
        ProblemType(
            "overloaded", 503, "Service overloaded", "no inference slot within queue_wait_s"
        ),
        ProblemType("timeout", 504, "Timeout", "inference over request_timeout_s"),
        ProblemType(
            "insufficient-storage",
            507,
            "Insufficient storage",
            "the styles folder cannot be written",
        ),
    )
}

# MotionError.kind -> slug ("invalid" is the default)
MOTION_KINDS = {
    "invalid": "invalid-input",
    "unusable": "unusable-input",
    "too-large": "too-large",
    "unsupported": "unsupported-media-type",
}


class Problem(BaseModel):
    """The body of every error response (for the OpenAPI schema; extension members allowed)."""

    model_config = ConfigDict(extra="allow")

    type: str
    title: str
    status: int
    detail: str
    instance: str
    request_id: str | None = None


def problem_kind(status: int) -> tuple[str, str]:
    """``(slug, title)`` for an HTTP status: the catalogue's first type with that status,
    else the status phrase."""
    for problem in CATALOGUE.values():
        if problem.status == status:
            return problem.slug, problem.title
    try:
        phrase = HTTPStatus(status).phrase
    except ValueError:
        phrase = f"HTTP {status}"
    return _slugify(phrase), phrase


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


class ServiceError(StarletteHTTPException):
    """An error the service reports as a problem. Subclasses name their catalogue entry
    (``slug``), so ``NotReady("models are loading")`` is enough; extension members are
    keyword arguments (``limit=...``), ``headers`` are added to the response.

    It is a Starlette ``HTTPException`` so that FastAPI lets it through untouched when raised
    while a request body is being read (see :mod:`service.middleware`).
    """

    slug: ClassVar[str] = "internal-error"

    def __init__(
        self, detail: str = "", *, headers: Mapping[str, str] | None = None, **ext: Any
    ) -> None:
        problem = CATALOGUE[self.slug]
        super().__init__(status_code=problem.status, detail=detail, headers=dict(headers or {}))
        self.title = problem.title
        self.ext = ext

    def __str__(self) -> str:
        return f"{self.status_code} {self.title}: {self.detail}"


class InvalidRequest(ServiceError):
    """A form field that is present but malformed (400)."""

    slug = "invalid-request"


class NotFound(ServiceError):
    """Unknown style, model or other named resource (404)."""

    slug = "not-found"


class Conflict(ServiceError):
    """The request contradicts what is stored: a name taken, a shipped style, a full store
    (409)."""

    slug = "conflict"


class InsufficientStorage(ServiceError):
    """What should be stored cannot be written (507)."""

    slug = "insufficient-storage"


class PayloadTooLarge(ServiceError):
    """Upload, clip or audio over a limit (413); pass ``limit=``."""

    slug = "too-large"


class UnsupportedMediaType(ServiceError):
    """A file format or content type we do not read (415)."""

    slug = "unsupported-media-type"


class Unauthorized(ServiceError):
    """No API key, or an unknown one, where keys are required (401 with
    ``WWW-Authenticate: Bearer``)."""

    slug = "unauthorized"


class Forbidden(ServiceError):
    """A known API key without the scope the route needs (403); pass ``required_scope=``."""

    slug = "forbidden"


class TooManyRequests(ServiceError):
    """An API key over its request rate or concurrency limit (429 with ``Retry-After``)."""

    slug = "too-many-requests"


class NotReady(ServiceError):
    """Models not loaded, still loading, or failed to load (503)."""

    slug = "not-ready"


class Overloaded(ServiceError):
    """No inference slot freed within ``queue_wait_s``, or the queue is full (503 with
    ``Retry-After``)."""

    slug = "overloaded"


class Timeout(ServiceError):
    """Inference ran past ``request_timeout_s`` (504); pass ``limit=``."""

    slug = "timeout"


def _slugify(text: str) -> str:
    return "-".join(text.lower().replace("'", "").split())


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
    assert isinstance(exc, ServiceError)
    return service_error_response(request.scope, exc)


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


def install_error_handlers(app: FastAPI) -> None:
    """Register every handler of this module on ``app`` (and document them in its OpenAPI)."""
    _document_problems(app)
    app.add_exception_handler(ServiceError, handle_service_error)
    app.add_exception_handler(MotionError, handle_motion_error)
    app.add_exception_handler(RequestValidationError, handle_validation_error)
    app.add_exception_handler(StarletteHTTPException, handle_http_exception)
    app.add_exception_handler(Exception, handle_unexpected_error)

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

======================  ======  ===============================================
slug                    status  raised for
======================  ======  ===============================================
invalid-request         400     fields missing or malformed (request validation)
invalid-input           400     a file we read but that is malformed (MotionError "invalid")
not-found               404     unknown path, style or model (:class:`NotFound`)
method-not-allowed      405     wrong method for a path
too-large               413     upload or clip over a limit (:class:`PayloadTooLarge`)
unsupported-media-type  415     a format we do not read (:class:`UnsupportedMediaType`)
unusable-input          422     well-formed but unusable (MotionError "unusable")
internal-error          500     a bug: logged with its traceback, never shown
not-ready               503     models not loaded (yet) (:class:`NotReady`)
timeout                 504     inference over ``request_timeout_s`` (:class:`Timeout`)
======================  ======  ===============================================

Library code raises :class:`motion.errors.MotionError`; service code raises a
:class:`ServiceError` subclass. Both become problems here and nowhere else.
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

logger = logging.getLogger(__name__)

PROBLEM_BASE = "https://motion-style.example/problems/"
PROBLEM_MEDIA_TYPE = "application/problem+json"

# MotionError.kind -> (status, slug, title)
MOTION_KINDS: dict[str, tuple[int, str, str]] = {
    "invalid": (400, "invalid-input", "Invalid input"),
    "unusable": (422, "unusable-input", "Unusable input"),
    "too-large": (413, "too-large", "Content too large"),
    "unsupported": (415, "unsupported-media-type", "Unsupported media type"),
}

# status -> (slug, title) for HTTP errors raised by the framework (routing, methods)
HTTP_PROBLEMS: dict[int, tuple[str, str]] = {
    400: ("invalid-request", "Invalid request"),
    404: ("not-found", "Not found"),
    405: ("method-not-allowed", "Method not allowed"),
    413: ("too-large", "Content too large"),
    415: ("unsupported-media-type", "Unsupported media type"),
    422: ("unusable-input", "Unusable input"),
    500: ("internal-error", "Internal server error"),
    503: ("not-ready", "Service not ready"),
    504: ("timeout", "Timeout"),
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
    """``(slug, title)`` for an HTTP status: from :data:`HTTP_PROBLEMS`, else its phrase."""
    if status in HTTP_PROBLEMS:
        return HTTP_PROBLEMS[status]
    try:
        phrase = HTTPStatus(status).phrase
    except ValueError:
        phrase = f"HTTP {status}"
    return _slugify(phrase), phrase


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` entries for a route's OpenAPI: the given statuses as problem+json."""
    return {
        status: {
            "content": {PROBLEM_MEDIA_TYPE: {"schema": Problem.model_json_schema()}},
            "description": problem_kind(status)[1],
        }
        for status in statuses
    }


class ServiceError(StarletteHTTPException):
    """An error the service reports as a problem: ``ServiceError(status, title, detail, **ext)``.

    Extension members are keyword arguments (``limit=...``); ``slug`` picks the problem type
    (default: from the status); ``headers`` are added to the response. Subclasses fix status,
    slug and title, so ``NotReady("models are loading")`` is enough.

    It is a Starlette ``HTTPException`` so that FastAPI lets it through untouched when raised
    while a request body is being read (see :mod:`service.middleware`).
    """

    status: int = 500
    slug: str = "internal-error"
    title: str = "Internal server error"

    def __init__(
        self,
        status: int | None = None,
        title: str | None = None,
        detail: str = "",
        *,
        slug: str | None = None,
        headers: Mapping[str, str] | None = None,
        **ext: Any,
    ) -> None:
        status = status or type(self).status
        super().__init__(status_code=status, detail=detail, headers=dict(headers or {}))
        default_slug, default_title = problem_kind(status)
        if title is not None:
            self.title = title
        elif type(self) is ServiceError:
            self.title = default_title
        if slug is not None:
            self.slug = slug
        elif type(self) is ServiceError:
            self.slug = default_slug
        self.ext = ext

    def __str__(self) -> str:
        return f"{self.status_code} {self.title}: {self.detail}"


class FixedServiceError(ServiceError):
    """A service error whose status, slug and title are class attributes; raise it with
    ``(detail, **ext)``. Subclass it to add a problem type (and add the slug to the table)."""

    def __init__(
        self, detail: str = "", *, headers: Mapping[str, str] | None = None, **ext: Any
    ) -> None:
        super().__init__(type(self).status, type(self).title, detail, headers=headers, **ext)


class NotFound(FixedServiceError):
    """Unknown style, model or other named resource (404)."""

    status, slug, title = 404, "not-found", "Not found"


class PayloadTooLarge(FixedServiceError):
    """Upload, clip or audio over a limit (413); pass ``limit=``."""

    status, slug, title = 413, "too-large", "Content too large"


class UnsupportedMediaType(FixedServiceError):
    """A file format or content type we do not read (415)."""

    status, slug, title = 415, "unsupported-media-type", "Unsupported media type"


class NotReady(FixedServiceError):
    """Models not loaded, still loading, or failed to load (503)."""

    status, slug, title = 503, "not-ready", "Service not ready"


class Timeout(FixedServiceError):
    """Inference ran past ``request_timeout_s`` (504); pass ``limit=``."""

    status, slug, title = 504, "timeout", "Timeout"


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
    out_headers = dict(headers or {})
    if request_id is not None:
        body["request_id"] = request_id
        out_headers.setdefault("X-Request-Id", request_id)
    return ProblemResponse(body, status_code=status, headers=out_headers)


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
    return problem_response(
        scope,
        status=500,
        slug="internal-error",
        title="Internal server error",
        detail="The server failed to process the request; the error has been logged.",
    )


async def handle_service_error(request: Request, exc: Exception) -> ProblemResponse:
    assert isinstance(exc, ServiceError)
    return service_error_response(request.scope, exc)


async def handle_motion_error(request: Request, exc: Exception) -> ProblemResponse:
    assert isinstance(exc, MotionError)
    status, slug, title = MOTION_KINDS.get(exc.kind, MOTION_KINDS["invalid"])
    return problem_response(
        request.scope, status=status, slug=slug, title=title, detail=exc.message, **exc.details()
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
    return problem_response(
        request.scope,
        status=400,
        slug="invalid-request",
        title="Invalid request",
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
        allow = (exc.headers or {}).get("Allow") or (exc.headers or {}).get("allow")
        detail = f"{method} is not allowed on {path}" + (f"; allowed: {allow}" if allow else "")
    else:
        detail = str(exc.detail)
    return problem_response(
        request.scope, status=status, slug=slug, title=title, detail=detail, headers=exc.headers
    )


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

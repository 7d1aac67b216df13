"""The one catalogue of the service's problems, and the exceptions that raise them.

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
exception classes here, and the answers and OpenAPI documentation of
:mod:`service.problems`, all read it. Library code raises :class:`motion.errors.MotionError`
(its ``kind`` names a slug of the catalogue); service code raises a :class:`ServiceError`
subclass. This module knows no HTTP framework, so engines and the clip toolkit can raise
them; :mod:`service.problems` turns both into responses, and nothing else does.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from http import HTTPStatus
from typing import Any, ClassVar

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


class ServiceError(Exception):
    """An error the service reports as a problem. Subclasses name their catalogue entry
    (``slug``), so ``NotReady("models are loading")`` is enough; extension members are
    keyword arguments (``limit=...``), ``headers`` are added to the response.

    It is plain data (status, type slug, title, detail, headers, extension members): engines
    and the clip toolkit raise it without knowing HTTP, and :mod:`service.problems` answers it.
    """

    slug: ClassVar[str] = "internal-error"

    def __init__(
        self, detail: str = "", *, headers: Mapping[str, str] | None = None, **ext: Any
    ) -> None:
        super().__init__(detail)
        problem = CATALOGUE[self.slug]
        self.status_code = problem.status
        self.title = problem.title
        self.detail = detail
        self.headers = dict(headers or {})
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

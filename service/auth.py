"""API keys on every request but the open ones, when ``MOTION_API_KEYS_FILE`` is set
(:mod:`service.api_keys` reads the file; :mod:`service.key_limits` counts per key).

A request brings its key as ``Authorization: Bearer KEY`` or ``X-API-Key: KEY``. Open
without a key: the health routes, the preview page and its files, the API documentation,
and ``/metrics`` unless ``MOTION_METRICS_KEY_REQUIRED``; everything else (every ``/v1``
route, and any path no route serves) is refused before its body is read:

- no key, or one the keys file does not hold: 401 with ``WWW-Authenticate: Bearer``;
- a key without the route's scope: 403 (a route that changes state declares
  ``openapi_extra=requires("manage")``; every other needs ``use``);
- a key over its requests a minute or in progress: 429 with ``Retry-After``.

All three are problems of :mod:`service.errors`. The key's *name* is put in
``scope["state"]["key_name"]`` (:func:`key_name`), from where the access log and the
per-key metric take it; the key itself is hashed and dropped, never logged or echoed.
Without a keys file everything stays open, and start-up warns when the service listens
beyond loopback.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from starlette.datastructures import Headers
from starlette.routing import compile_path
from starlette.types import ASGIApp, Receive, Scope, Send

from service.api_keys import ApiKey, KeysFile
from service.config import Settings
from service.errors import Forbidden, ServiceError, TooManyRequests, Unauthorized
from service.key_limits import KeyLimits, Slot
from service.log import key_name_var
from service.problems import problem_responses, service_error_response

logger = logging.getLogger(__name__)

SCOPE_EXTENSION = "x-required-scope"
REALM = 'Bearer realm="motion-style"'
OPEN_PATHS = frozenset(
    {
        "/healthz",
        "/readyz",
        "/v2/health/live",
        "/v2/health/ready",
        "/",
        "/docs",
        "/docs/oauth2-redirect",
        "/redoc",
        "/openapi.json",
    }
)
OPEN_PREFIXES = ("/static/",)


def requires(scope: str) -> dict[str, Any]:
    """``openapi_extra`` of a route that needs ``scope`` (``"manage"``) instead of ``use``."""
    return {SCOPE_EXTENSION: scope}


def key_name(scope: Scope) -> str | None:
    """The name of the key the request came with (None where keys are off)."""
    return (scope.get("state") or {}).get("key_name")


def presented_key(scope: Scope) -> str | None:
    """The key of ``Authorization: Bearer KEY``, else of ``X-API-Key``, else None."""
    headers = Headers(scope=scope)
    scheme, _, token = headers.get("authorization", "").strip().partition(" ")
    if scheme.lower() == "bearer" and token.strip():
        return token.strip()
    return headers.get("x-api-key", "").strip() or None


def is_open(path: str, metrics_open: bool) -> bool:
    return (
        path in OPEN_PATHS
        or path.startswith(OPEN_PREFIXES)
        or (metrics_open and path == "/metrics")
    )


def required_scope(scope: Scope) -> str:
    """The scope the route that will answer the request declares (``use`` when it declares
    none, or no route matches), read from the app's OpenAPI operations."""
    app = scope.get("app")
    if app is None:
        return "use"
    table = getattr(app.state, "route_scopes", None)
    if table is None:
        table = app.state.route_scopes = _route_scopes(app)
    path, method = scope.get("path", ""), scope.get("method", "").lower()
    for regex, scopes, otherwise in table:
        if regex.match(path):
            return scopes.get(method, otherwise)
    return "use"


def _route_scopes(app: FastAPI) -> list[tuple[re.Pattern, dict[str, str], str]]:
    """``(path regex, {method: scope}, scope of other methods)`` for every documented path,
    fixed paths before templated ones. A schema that cannot be built makes every route
    need ``manage``: refusing is safer than letting a ``use`` key by."""
    out = []
    try:
        paths = app.openapi().get("paths", {})
    except Exception:
        logger.exception("cannot read the routes' scopes: every route needs 'manage'")
        return [(re.compile(""), {}, "manage")]
    for template, item in paths.items():
        scopes = {m: op.get(SCOPE_EXTENSION, "use") for m, op in item.items()}
        out.append((compile_path(template)[0], scopes, "{" in template))
    out.sort(key=lambda row: row[2])
    return [(regex, scopes, "use") for regex, scopes, _ in out]


class ApiKeyMiddleware:
    """Refuses requests without a known key with the scope (401/403) or over the key's
    limits (429); see the module's documentation."""

    def __init__(self, app: ASGIApp, keys: KeysFile, limits: KeyLimits, metrics_open: bool):
        self.app = app
        self.keys = keys
        self.limits = limits
        self.metrics_open = metrics_open

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or is_open(scope["path"], self.metrics_open):
            await self.app(scope, receive, send)
            return
        presented = presented_key(scope)
        if presented is None:
            error = Unauthorized(
                "this service needs an API key: send 'Authorization: Bearer KEY' or "
                "'X-API-Key: KEY'",
                headers={"WWW-Authenticate": REALM},
            )
            await service_error_response(scope, error)(scope, receive, send)
            return
        entry = self.keys.identify(presented)
        del presented
        if entry is None:
            error = Unauthorized(
                "the API key is not known to this service (or it was revoked)",
                headers={"WWW-Authenticate": f'{REALM}, error="invalid_token"'},
            )
            await service_error_response(scope, error)(scope, receive, send)
            return
        scope.setdefault("state", {})["key_name"] = entry.name
        token = key_name_var.set(entry.name)
        try:
            slot = self._admit(scope, entry)
            if isinstance(slot, ServiceError):
                await service_error_response(scope, slot)(scope, receive, send)
                return
            try:
                await self.app(scope, receive, send)
            finally:
                slot.release()
        finally:
            key_name_var.reset(token)

    def _admit(self, scope: Scope, entry: ApiKey) -> Slot | ServiceError:
        """One of ``entry``'s slots, held for the request, when it may make it now; else
        the 403 or 429 to answer."""
        needed = required_scope(scope)
        if not entry.allows(needed):
            return Forbidden(
                f"the key {entry.name!r} has the scopes {', '.join(sorted(entry.scopes))}; "
                f"{scope['method']} {scope['path']} needs {needed!r}",
                headers={
                    "WWW-Authenticate": f'{REALM}, error="insufficient_scope", scope="{needed}"'
                },
                required_scope=needed,
                key_name=entry.name,
            )
        slot = self.limits.acquire(entry.name)
        if slot is None:
            limit = self.limits.max_concurrent
            return TooManyRequests(
                f"the key {entry.name!r} has {limit} requests in progress, its most "
                "(key_max_concurrent)",
                headers={"Retry-After": "1"},
                limit=limit,
                limit_name="key_max_concurrent",
                key_name=entry.name,
            )
        wait = self.limits.take(entry.name)
        if wait > 0:
            slot.release()
            per_minute = self.limits.per_second * 60.0
            return TooManyRequests(
                f"the key {entry.name!r} is over its {per_minute:g} requests a minute "
                f"(key_requests_per_minute): retry in {math.ceil(wait)} s",
                headers={"Retry-After": str(max(1, math.ceil(wait)))},
                limit=per_minute,
                limit_name="key_requests_per_minute",
                key_name=entry.name,
            )
        return slot


def _document_security(app: FastAPI, metrics_open: bool) -> None:
    """The OpenAPI schema names the two ways to send a key and, for each operation that
    needs one, its scope and the 401/403/429 answers."""
    build_schema = app.openapi

    def openapi() -> dict[str, Any]:
        schema = build_schema()
        schemes = schema.setdefault("components", {}).setdefault("securitySchemes", {})
        schemes["bearer"] = {
            "type": "http",
            "scheme": "bearer",
            "description": "an API key (`python -m service keys add`)",
        }
        schemes["apiKey"] = {"type": "apiKey", "in": "header", "name": "X-API-Key"}
        for path, item in schema.get("paths", {}).items():
            if is_open(path, metrics_open):
                continue
            for operation in item.values():
                needed = operation.get(SCOPE_EXTENSION, "use")
                operation["security"] = [{"bearer": [needed]}, {"apiKey": [needed]}]
                responses = operation.setdefault("responses", {})
                for status, answer in problem_responses(401, 403, 429).items():
                    responses.setdefault(str(status), answer)
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def install(app: FastAPI, settings: Settings) -> None:
    """Add the key check to ``app`` when ``settings.api_keys_file`` is set (raises
    :class:`~service.api_keys.KeysFileError` when the file cannot be read). Call it
    between the upload limit and the request context middleware."""
    app.state.key_limits = None
    if settings.api_keys_file is None:
        return
    keys = KeysFile(settings.api_keys_file)
    folder = settings.key_state_dir
    app.state.key_state_made = folder is None
    if folder is None:
        folder = Path(tempfile.mkdtemp(prefix="motion-keys-"))
    limits = KeyLimits(
        folder, settings.key_requests_per_minute, settings.key_burst, settings.key_max_concurrent
    )
    app.state.key_limits = limits
    metrics_open = not settings.metrics_key_required
    app.add_middleware(ApiKeyMiddleware, keys=keys, limits=limits, metrics_open=metrics_open)
    _document_security(app, metrics_open)


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def log_startup(settings: Settings) -> None:
    """Say whether keys are required; warn when none are and others can reach the service."""
    if settings.api_keys_file is not None:
        logger.info("API keys required (MOTION_API_KEYS_FILE=%s)", settings.api_keys_file)
        room = settings.workers * (settings.max_concurrent_inferences + settings.max_queued)
        if settings.key_max_concurrent == 0 or settings.key_max_concurrent >= room:
            logger.warning(
                "one API key may hold every inference slot and queue place of this replica "
                "(%d): set MOTION_KEY_MAX_CONCURRENT below it so that it cannot starve others",
                room,
            )
    elif not is_loopback(settings.host):
        logger.warning(
            "no API keys: anyone who reaches %s:%d can use this service and delete its "
            "registered styles; set MOTION_API_KEYS_FILE (docs/api-keys.md)",
            settings.host,
            settings.port,
        )


def close(app: FastAPI) -> None:
    limits: KeyLimits | None = getattr(app.state, "key_limits", None)
    if limits is None:
        return
    limits.close()
    if getattr(app.state, "key_state_made", False):
        shutil.rmtree(limits.folder, ignore_errors=True)

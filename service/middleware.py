"""Pure ASGI middleware: request context (id, access log, last-resort 500) and upload limit.

Order, outermost first: :class:`RequestContextMiddleware`, :class:`UploadLimitMiddleware`,
then FastAPI's exception handling and routing. So a 413 is sent before routing, and every
response, errors included, carries ``X-Request-Id``.
"""

from __future__ import annotations

import logging
import re
import time
import uuid

from starlette.datastructures import Headers, MutableHeaders
from starlette.routing import Mount, compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service import metrics
from service.errors import PayloadTooLarge
from service.log import request_id_var
from service.problems import ReadRefused, internal_error_response, service_error_response

logger = logging.getLogger("service.access")
error_logger = logging.getLogger("service.errors")

REQUEST_ID_HEADER = "X-Request-Id"
_REQUEST_ID = re.compile(r"[A-Za-z0-9._-]{1,128}")


def accept_request_id(value: str | None) -> str:
    """The client's request id if it is 1-128 characters of ``[A-Za-z0-9._-]``, else a new one.

    An id that does not fit is replaced, not repaired, so a log line never holds client
    bytes other than those characters.
    """
    if value is not None and _REQUEST_ID.fullmatch(value):
        return value
    return uuid.uuid4().hex


def endpoint_of(scope: Scope) -> str:
    """The route template that handled (or would have handled) the request, for metric labels:
    ``/v1/models``, ``/static`` for the static mount, :data:`metrics.UNMATCHED` for none."""
    path = getattr(scope.get("route"), "path", None)
    if isinstance(path, str) and path:
        return path
    # Answered before routing (the upload limit) or no route matched: find the template.
    app = scope.get("app")
    if app is None:
        return metrics.UNMATCHED
    templates = getattr(app.state, "route_templates", None)
    if templates is None:
        templates = app.state.route_templates = _route_templates(app)
    request_path = scope.get("path", "")
    for regex, template in templates:
        if regex.match(request_path):
            return template
    return metrics.UNMATCHED


def _route_templates(app) -> list[tuple[re.Pattern, str]]:
    """``(regex, template)`` for every documented path and every mount (``/static``)."""
    out = []
    try:
        paths = list(app.openapi().get("paths", {}))
    except Exception:  # a schema that cannot be built must not break the bookkeeping
        error_logger.exception("cannot list the routes for metric labels")
        paths = []
    for template in paths:
        out.append((compile_path(template)[0], template))
    for route in app.routes:
        if isinstance(route, Mount) and route.path:
            out.append((re.compile(re.escape(route.path) + "(/.*)?$"), route.path))
    return out


class RequestContextMiddleware:
    """Gives each HTTP request an id (``scope["state"]["request_id"]`` and the log context),
    echoes it as ``X-Request-Id``, writes one access-log line per request (with ``method``,
    ``path``, ``status``, ``duration_ms`` and the API key's name, ``key``, as structured
    fields), counts it in the request
    metrics, and turns an exception that escaped every handler into a logged 500 problem
    without a traceback."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        request_id = accept_request_id(Headers(scope=scope).get(REQUEST_ID_HEADER))
        scope.setdefault("state", {})["request_id"] = request_id
        token = request_id_var.set(request_id)
        started_at = time.perf_counter()
        status = 0

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                headers = MutableHeaders(scope=message)
                if REQUEST_ID_HEADER not in headers:
                    headers[REQUEST_ID_HEADER] = request_id
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        except Exception:
            key = scope["state"].get("key_name")  # the API key's name (service.auth)
            error_logger.exception(
                "unhandled error in %s %s",
                scope["method"],
                scope["path"],
                extra={"key": key} if key is not None else None,
            )
            if status:  # the response had started: nothing sensible left to send
                raise
            await internal_error_response(scope)(scope, receive, send_with_id)
        finally:
            elapsed = time.perf_counter() - started_at
            method, path = scope["method"], scope["path"]
            endpoint = endpoint_of(scope)
            metrics.observe_request(endpoint, method, status, elapsed)
            key = scope["state"].get("key_name")  # set by service.auth: a name, never the key
            if key is not None:
                metrics.count_key_request(key, endpoint, status)
            logger.info(
                "%s %s %s %.1fms%s",
                method,
                path,
                status or "-",
                elapsed * 1000.0,
                f" key={key}" if key is not None else "",
                extra={
                    "method": method,
                    "path": path,
                    "status": status or None,
                    "duration_ms": round(elapsed * 1000.0, 3),
                    **({"key": key} if key is not None else {}),
                },
            )
            request_id_var.reset(token)


def _content_length(scope: Scope) -> int | None:
    value = Headers(scope=scope).get("content-length")
    try:
        return int(value) if value is not None else None
    except ValueError:
        return None


class UploadLimitMiddleware:
    """Rejects request bodies over ``max_bytes`` with a 413 problem.

    A declared ``Content-Length`` over the limit is answered at once, before routing and
    without reading the body. Otherwise (chunked uploads, or a client that lies) the bytes
    are counted as the app reads them, and reading stops with a :class:`PayloadTooLarge`
    (carried by :class:`~service.problems.ReadRefused`) the moment the count passes the
    limit, so at most one chunk over the limit is ever held.
    If the app swallows that error and answers something else, the 413 is sent instead.
    """

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    def _too_large(self) -> PayloadTooLarge:
        return PayloadTooLarge(
            f"The request body exceeds the upload limit of {self.max_bytes} bytes",
            limit=self.max_bytes,
            headers={"Connection": "close"},
        )

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        declared = _content_length(scope)
        if declared is not None and declared > self.max_bytes:
            await service_error_response(scope, self._too_large())(scope, receive, send)
            return

        received = 0
        exceeded = False
        started = False
        replaced = False

        async def limited_receive() -> Message:
            nonlocal received, exceeded
            if exceeded:
                raise ReadRefused(self._too_large())
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    exceeded = True
                    raise ReadRefused(self._too_large())
            return message

        async def guarded_send(message: Message) -> None:
            nonlocal started, replaced
            if replaced:
                return
            if message["type"] == "http.response.start":
                started = True
                if exceeded and message["status"] != 413:
                    replaced = True
                    await service_error_response(scope, self._too_large())(scope, receive, send)
                    return
            await send(message)

        try:
            await self.app(scope, limited_receive, guarded_send)
        except Exception:
            if not exceeded or started:
                raise
            await service_error_response(scope, self._too_large())(scope, receive, send)

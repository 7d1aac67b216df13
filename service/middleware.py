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
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.errors import PayloadTooLarge, internal_error_response, service_error_response
from service.log import request_id_var

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


class RequestContextMiddleware:
    """Gives each HTTP request an id (``scope["state"]["request_id"]`` and the log context),
    echoes it as ``X-Request-Id``, writes one access-log line per request, and turns an
    exception that escaped every handler into a logged 500 problem without a traceback."""

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
            error_logger.exception("unhandled error in %s %s", scope["method"], scope["path"])
            if status:  # the response had started: nothing sensible left to send
                raise
            await internal_error_response(scope)(scope, receive, send_with_id)
        finally:
            elapsed_ms = (time.perf_counter() - started_at) * 1000.0
            logger.info(
                "%s %s %s %.1fms", scope["method"], scope["path"], status or "-", elapsed_ms
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
    are counted as the app reads them, and reading stops with :class:`PayloadTooLarge` the
    moment the count passes the limit, so at most one chunk over the limit is ever held.
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
                raise self._too_large()
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    exceeded = True
                    raise self._too_large()
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

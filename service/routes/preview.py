"""``GET /``: the preview page, and ``/static/*``: its script, styles and vendored three.js.

Everything the page loads comes from this server (the Content-Security-Policy says so), so
it works where no CDN is reachable.
"""

from __future__ import annotations

from pathlib import Path

import anyio
from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"

# 'self' only: no CDN, no inline script; blob: for the result download link, data: for the
# empty favicon. WebGL needs nothing more.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
PAGE_HEADERS = {
    "Content-Security-Policy": CONTENT_SECURITY_POLICY,
    "X-Content-Type-Options": "nosniff",
    "Cache-Control": "no-cache",
}

router = APIRouter(tags=["preview"])


async def _no_request() -> Message:
    """A receive that never returns: Starlette's file responses read the request while they
    send only to notice a disconnect, and a body sent along (GET with 400 kB chunked) then
    passed the upload limit after the response had started: a 500. The files never need
    the request, so it stays unread."""
    await anyio.sleep_forever()
    raise AssertionError("unreachable")


def _without_range(scope: Scope) -> Scope:
    if scope["type"] != "http":
        return scope
    headers = [(k, v) for k, v in scope["headers"] if k not in (b"range", b"if-range")]
    return {**scope, "headers": headers}


class WholeFileResponse(FileResponse):
    """A file, always whole: Range is ignored (RFC 9110 allows it), so a malformed range is
    never Starlette's plain-text 400/416 instead of a problem document."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        await super().__call__(_without_range(scope), _no_request, send)


class WholeFiles:
    """The same for a static-files app (which never reads the request either)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        await self.app(_without_range(scope), _no_request, send)


@router.get(
    "/",
    summary="Preview page: upload a clip, pick a style, compare input and result in 3D",
    response_class=HTMLResponse,
    responses={200: {"content": {"text/html": {"schema": {"type": "string"}}}}},
)
async def get_preview() -> FileResponse:
    return WholeFileResponse(
        STATIC_DIR / "index.html", media_type="text/html", headers=PAGE_HEADERS
    )


def install_preview(app: FastAPI) -> None:
    """Add ``GET /`` and mount ``/static`` on ``app``."""
    app.include_router(router)
    app.mount("/static", WholeFiles(StaticFiles(directory=STATIC_DIR)), name="static")

"""The motion-style service over HTTP with the standard library (Blender ships no httpx)."""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
import uuid
from typing import NamedTuple

API_KEY_ENV = "MOTION_API_KEY"


class ServiceError(Exception):
    """The service could not be reached or answered with a problem; the message says which."""


def _with_key(request: urllib.request.Request, api_key: str) -> urllib.request.Request:
    """``request`` with ``Authorization: Bearer`` the key given, else ``$MOTION_API_KEY``."""
    key = (api_key or os.environ.get(API_KEY_ENV, "")).strip()
    if key:
        request.add_header("Authorization", f"Bearer {key}")
    return request


class Answer(NamedTuple):
    """A restyled clip and what the service warned of it."""

    bvh: bytes
    warnings: list[str]


def warnings_of(header: str | None) -> list[str]:
    """The service's ``X-Warnings`` header (a JSON array of strings) as a list."""
    if not header:
        return []
    try:
        said = json.loads(header)
    except ValueError:
        return [header]
    return [str(w) for w in said] if isinstance(said, list) else [header]


def _open(request: urllib.request.Request, timeout: float) -> tuple[bytes, list[str]]:
    """The answer's body and its warnings."""
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            return response.read(), warnings_of(response.headers.get("X-Warnings"))
    except urllib.error.HTTPError as exc:
        body = exc.read()
        try:
            problem = json.loads(body)
            detail = problem.get("detail") or problem.get("title")
        except (ValueError, AttributeError):
            detail = body[:200].decode("utf-8", "replace")
        if exc.code == 401:
            detail += " (set the API key in the add-on's preferences or MOTION_API_KEY)"
        raise ServiceError(f"{exc.code}: {detail}") from None
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise ServiceError(f"cannot reach {request.full_url}: {reason}") from None


def styles(server: str, api_key: str = "", timeout: float = 10.0) -> list[str]:
    """Names of the translator's styles (``GET /v1/styles``), shipped and registered, as a
    request names them: ``library:style`` where two models offer one name."""
    request = _with_key(urllib.request.Request(server.rstrip("/") + "/v1/styles"), api_key)
    body, _ = _open(request, timeout)
    try:
        return listing_of(json.loads(body).get("translator", []))
    except (ValueError, KeyError, TypeError, AttributeError):
        raise ServiceError("GET /v1/styles did not answer with a style list") from None


def listing_of(styles: list[dict]) -> list[str]:
    """The names to send for a family's styles: each bare, or ``qualified_name`` where
    several models share the name (a bare one would be refused as ambiguous)."""
    counts: dict[str, int] = {}
    for style in styles:
        counts[style["name"]] = counts.get(style["name"], 0) + 1
    return [
        style.get("qualified_name", style["name"]) if counts[style["name"]] > 1 else style["name"]
        for style in styles
    ]


def transfer(
    server: str,
    content: bytes,
    style_name: str,
    strength: float,
    api_key: str = "",
    timeout: float = 300.0,
    keep_timing: bool = False,
) -> Answer:
    """BVH of ``content`` (BVH bytes) restyled by ``POST /v1/transfer``, and the service's
    warnings; with ``keep_timing`` without the style's time warp (as many frames as sent)."""
    boundary = uuid.uuid4().hex
    parts = []
    fields = [("style_name", style_name), ("strength", repr(float(strength)))]
    if keep_timing:
        fields.append(("time_warp", "false"))
    for name, value in fields:
        parts.append(
            f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'.encode()
        )
    parts.append(
        f'--{boundary}\r\nContent-Disposition: form-data; name="content"; '
        f'filename="content.bvh"\r\nContent-Type: application/octet-stream\r\n\r\n'.encode()
        + content
        + b"\r\n"
    )
    parts.append(f"--{boundary}--\r\n".encode())
    request = urllib.request.Request(
        server.rstrip("/") + "/v1/transfer",
        data=b"".join(parts),
        headers={"Content-Type": f"multipart/form-data; boundary={boundary}"},
        method="POST",
    )
    return Answer(*_open(_with_key(request, api_key), timeout))

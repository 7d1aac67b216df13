"""HTTP answers of the data plane's results: a clip as a BVH, GLB or FBX attachment, or as a JSON
object with ``?format=json``, with the headers every inference answer carries."""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import PurePath
from typing import Any

from fastapi import Request
from fastapi.responses import JSONResponse, Response

from service.clips import FILE_FORMATS, Result
from service.problems import problem_responses

BVH_MEDIA_TYPE = "text/plain; charset=utf-8"
GLB_MEDIA_TYPE = "model/gltf-binary"
FBX_MEDIA_TYPE = "application/octet-stream"  # FBX has no registered media type
WARNINGS_HEADER_CHARS = 4096  # under the 8 KB header blocks that proxies and clients accept


def _header(description: str, kind: str = "string") -> dict:
    return {"description": description, "schema": {"type": kind}}


ANSWER_HEADERS = {
    "X-Model-Version": _header("the model that answered, name/version"),
    "X-Frames": _header("frames in the answer", "integer"),
    "X-Fps": _header("the answer's frame rate", "number"),
    "Server-Timing": _header("each stage's time"),
    "X-Loop": _header("true or false: whether the clip was taken as a cycle (restyling only)"),
    "X-Warnings": _header(
        "the warnings, as a JSON array of strings; absent without any (a last entry counts "
        "those past 4 KB: ?format=json has them all)"
    ),
}
DANCE_HEADERS = {
    "X-Dance-Genre": _header("the genre danced: the one given, or the one predicted"),
    "X-Dance-Tempo": _header("beats a minute the steps follow, at the genre's level", "number"),
    "X-Beat-Alignment": _header("the dance's beats against the music's", "number"),
    "X-Beat-Alignment-Chance": _header("the same score against shifted beats", "number"),
}


def clip_responses(description: str, dance: bool = False) -> dict:
    """OpenAPI ``responses`` of a route that answers BVH, GLB or FBX (or JSON with
    ``?format=json``), with the headers the answer carries (a dance's too)."""
    return {
        200: {
            "content": {
                "text/plain": {},
                GLB_MEDIA_TYPE: {},
                FBX_MEDIA_TYPE: {},
                "application/json": {},
            },
            "description": description,
            "headers": {**ANSWER_HEADERS, **(DANCE_HEADERS if dance else {})},
        },
        **problem_responses(400, 404, 413, 415, 422, 503, 504),
    }


def route_template(request: Request) -> str:
    """The path template of the route that serves ``request`` (a metric label)."""
    route = request.scope.get("route")
    return getattr(route, "path", None) or request.scope.get("path", "")


def _filename(upload_name: str | None, suffix: str, extension: str = "bvh") -> str:
    stem = PurePath(upload_name or "motion").stem or "motion"
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem)[:80] or "motion"
    return f"{stem}_{re.sub(r'[^A-Za-z0-9._-]+', '_', suffix)}.{extension}"


def timing_headers(result: Any) -> dict[str, str]:
    """``X-Model-Version`` and ``Server-Timing`` of a result."""
    name, version = result.model
    return {
        "X-Model-Version": f"{name}/{version}",
        "Server-Timing": result.timer.server_timing() if result.timer else "",
    }


def warning_headers(warnings: Sequence[str]) -> dict[str, str]:
    """``X-Warnings``, the warnings as a JSON array of strings in ASCII, so that a BVH, GLB or
    FBX answer carries them too; none without warnings. Those that do not fit in
    ``WARNINGS_HEADER_CHARS`` are counted in a last string instead (``?format=json`` has them
    all)."""
    if not warnings:
        return {}
    kept = list(warnings)
    value = json.dumps(kept)
    while len(value) > WARNINGS_HEADER_CHARS:
        kept.pop()
        left = len(warnings) - len(kept)
        value = json.dumps([*kept, f"{left} more warning{'s' * (left > 1)}: ?format=json"])
    return {"X-Warnings": value}


def dance_headers(dance: dict) -> dict[str, str]:
    """What a dance answer says of the dance: the genre danced, the tempo its steps follow
    and its beat alignment, with the alignment of shifted beats (chance)."""
    return {
        "X-Dance-Genre": dance["genre"],
        "X-Dance-Tempo": f"{dance['tempo_bpm']:g}",
        "X-Beat-Alignment": f"{dance['beat_alignment']:g}",
        "X-Beat-Alignment-Chance": f"{dance['beat_alignment_chance']:g}",
    }


def timings_ms(result: Any) -> dict[str, float]:
    return {k: round(v, 2) for k, v in (result.timer.ms if result.timer else {}).items()}


def respond(result: Result, *, upload_name: str | None = None) -> Response:
    """The answer in ``result.format``: BVH as a ``text/plain`` attachment, GLB as a
    ``model/gltf-binary`` one or FBX as an ``application/octet-stream`` one, with ``X-Model-Version``, ``X-Frames``, ``X-Fps`` and
    ``Server-Timing`` (``X-Request-Id`` is the middleware's), and ``X-Warnings`` where there
    are warnings; or for ``json`` the object
    ``{"bvh", "frames", "fps", "model", "timings_ms", "warnings", "source_format"}`` (and
    ``rig``, and ``loop``: whether the clip was taken as a loop; same headers). A clip's
    answer says ``X-Loop`` too; a dance's says its genre, tempo and beat alignment
    (``dance`` in JSON, ``X-Dance-Genre``, ``X-Dance-Tempo``, ``X-Beat-Alignment`` and
    ``X-Beat-Alignment-Chance``)."""
    name, version = result.model
    headers = {
        **timing_headers(result),
        "X-Frames": str(result.frames),
        "X-Fps": f"{result.fps:g}",
        **warning_headers(result.warnings),
    }
    loop, dance = result.loop, result.dance
    if loop is not None:
        headers["X-Loop"] = "true" if loop else "false"
    if dance is not None:
        headers.update(dance_headers(dance))
    if result.format == "json":
        body = {
            "bvh": result.bvh,
            "frames": result.frames,
            "fps": result.fps,
            "model": {"name": name, "version": version},
            "timings_ms": timings_ms(result),
            "warnings": result.warnings,
            "source_format": result.source_format,
        }
        if result.rig is not None:
            body["rig"] = result.rig
        if loop is not None:
            body["loop"] = loop
        if dance is not None:
            body["dance"] = dance
        return JSONResponse(body, headers=headers)
    if result.format in FILE_FORMATS:
        filename = _filename(upload_name, result.suffix, result.format)
        headers["Content-Disposition"] = f'attachment; filename="{filename}"'
        media_type = GLB_MEDIA_TYPE if result.format == "glb" else FBX_MEDIA_TYPE
        return Response(result.binary, media_type=media_type, headers=headers)
    filename = _filename(upload_name, result.suffix)
    headers["Content-Disposition"] = f'attachment; filename="{filename}"'
    return Response(result.bvh, media_type=BVH_MEDIA_TYPE, headers=headers)

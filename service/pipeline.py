"""Request plumbing every family shares: an uploaded BVH onto the canonical skeleton, and a
canonical result back onto the request's own skeleton as a BVH (or JSON) response.

A route reads the upload on the event loop (:func:`read_upload`), then does the blocking
rest in the inference pool::

    data = await pipeline.read_upload(content, settings)
    mapping = pipeline.parse_mapping(mapping_field)

    def work():
        timer = metrics.StageTimer(engine.name)
        clip = pipeline.load_clip(data, settings, timer, mapping=mapping)
        canon = engine.stylize(clip.canonical, ...)                # the family's own work
        return pipeline.finish(clip, canon, timer)                 # -> Result

    result = await run_inference(request, work)
    return pipeline.respond(request, result, engine, fmt=format, name="stylized")

Errors: a malformed BVH is a 400 problem with ``line``; a media type that is not text a
415; more than ``max_frames`` frames a 413 with ``limit``; a skeleton that cannot be mapped
a 422 with ``unmapped``; a ``mapping`` that is not a JSON object of names a 400.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any, Literal

from fastapi import Request, UploadFile
from fastapi.responses import JSONResponse, Response

from motion import bvh, retarget
from motion import canonical as C
from motion.skeleton import Motion
from service import limits, metrics
from service.config import Settings
from service.engines.base import Engine
from service.errors import PayloadTooLarge, ServiceError, UnsupportedMediaType, problem_responses

Format = Literal["bvh", "json"]

# Media types a BVH upload may carry (clients label text files in many ways).
TEXT_TYPES = ("text/", "application/octet-stream", "application/x-bvh", "application/bvh")
BVH_MEDIA_TYPE = "text/plain; charset=utf-8"


def bvh_responses(description: str) -> dict:
    """OpenAPI ``responses`` of a route that answers BVH (or JSON with ``?format=json``)."""
    return {
        200: {
            "content": {"text/plain": {}, "application/json": {}},
            "description": description,
        },
        **problem_responses(400, 404, 413, 415, 422, 503, 504),
    }


class InvalidField(ServiceError):
    """A form field that is present but malformed (400 invalid-request)."""

    def __init__(self, detail: str, **ext: Any) -> None:
        super().__init__(400, "Invalid request", detail, slug="invalid-request", **ext)


async def read_upload(
    upload: UploadFile,
    settings: Settings,
    *,
    field: str = "content",
    accept: tuple[str, ...] = TEXT_TYPES,
    what: str = "a BVH text file",
) -> bytes:
    """The bytes of an uploaded file: 415 when its media type starts with none of ``accept``
    (``'<field>' must be <what>``), 413 over ``max_upload_bytes`` (the middleware usually
    stops it first), 400 when empty."""
    media = (upload.content_type or "").split(";")[0].strip().lower()
    if media and not media.startswith(accept):
        raise UnsupportedMediaType(
            f"'{field}' must be {what}, got media type {media!r}", field=field
        )
    data = await upload.read(settings.max_upload_bytes + 1)
    if len(data) > settings.max_upload_bytes:
        raise PayloadTooLarge(
            f"'{field}' is over {settings.max_upload_bytes} bytes",
            limit=settings.max_upload_bytes,
            limit_name="max_upload_bytes",
        )
    if not data.strip():
        raise InvalidField(f"'{field}' is empty", field=field)
    return data


def parse_mapping(text: str | None) -> dict[str, str] | None:
    """The optional ``mapping`` form field: a JSON object of joint names (either way round);
    400 when it is not one."""
    if text is None or not text.strip():
        return None
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise InvalidField(f"'mapping' is not JSON: {exc}", field="mapping") from None
    if not isinstance(value, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in value.items()
    ):
        raise InvalidField("'mapping' must be a JSON object of joint names", field="mapping")
    return value


@dataclass
class Clip:
    """An uploaded clip: as sent (``original``), its rig, and on the canonical skeleton at
    30 fps (``canonical``)."""

    original: Motion
    rig: retarget.Rig
    canonical: Motion


@dataclass
class Result:
    """A finished request: BVH text on the request's skeleton, its frames and rate, the
    stage timings and any warnings."""

    bvh: str
    frames: int
    fps: float
    timer: metrics.StageTimer
    warnings: list[str] = field(default_factory=list)
    rig: dict | None = None  # the request skeleton's mapping, how found, confidence (JSON)


def load_clip(
    data: bytes | str,
    settings: Settings,
    timer: metrics.StageTimer,
    *,
    mapping: dict[str, str] | None = None,
    what: str = "content",
) -> Clip:
    """Parse (400 with ``line``), check frames (413 with ``limit``), map the skeleton
    (422 with ``unmapped``) and retarget to canonical at 30 fps. Blocking."""
    with timer.stage("parse"):
        original = limits.read_bvh(data, settings, what=what)
    with timer.stage("retarget"):
        rig = retarget.make_rig(original.skeleton, original, mapping=mapping)
        canonical = retarget.to_canonical(original, rig, fps=C.FPS)
    limits.check_frames(canonical, settings, what=what)
    return Clip(original, rig, canonical)


def finish(clip: Clip, canon: Motion, timer: metrics.StageTimer, warnings=()) -> Result:
    """The canonical result back on the clip's own skeleton, frame rate and frame count,
    as BVH text. Blocking."""
    with timer.stage("retarget_back"):
        out = retarget.from_canonical(canon, clip.rig, like=clip.original)
    with timer.stage("write"):
        text = bvh.dumps(out)
    return Result(text, out.num_frames, float(out.fps), timer, list(warnings), clip.rig.report())


def _filename(upload_name: str | None, suffix: str) -> str:
    stem = PurePath(upload_name or "motion").stem or "motion"
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem)[:80] or "motion"
    return f"{stem}_{re.sub(r'[^A-Za-z0-9._-]+', '_', suffix)}.bvh"


def respond(
    request: Request,
    result: Result,
    engine: Engine,
    *,
    fmt: Format = "bvh",
    upload_name: str | None = None,
    suffix: str = "styled",
    endpoint: str | None = None,
) -> Response:
    """The BVH as ``text/plain`` attachment with ``X-Request-Id``, ``X-Model-Version``,
    ``X-Frames``, ``X-Fps`` and ``Server-Timing``, or with ``fmt="json"`` the object
    ``{"bvh", "frames", "fps", "model", "timings_ms", "warnings"}`` (same headers)."""
    metrics.count_frames(endpoint or request.url.path, engine.name, result.frames)
    request_id = (request.scope.get("state") or {}).get("request_id", "")
    headers = {
        "X-Model-Version": f"{engine.name}/{engine.version}",
        "X-Frames": str(result.frames),
        "X-Fps": f"{result.fps:g}",
        "Server-Timing": result.timer.server_timing(),
    }
    if request_id:
        headers["X-Request-Id"] = request_id
    if fmt == "json":
        body = {
            "bvh": result.bvh,
            "frames": result.frames,
            "fps": result.fps,
            "model": {"name": engine.name, "version": engine.version},
            "timings_ms": {k: round(v, 2) for k, v in result.timer.ms.items()},
            "warnings": result.warnings,
        }
        if result.rig is not None:
            body["rig"] = result.rig
        return JSONResponse(body, headers=headers)
    headers["Content-Disposition"] = f'attachment; filename="{_filename(upload_name, suffix)}"'
    return Response(result.bvh, media_type=BVH_MEDIA_TYPE, headers=headers)

"""The one-way path of a request: parse -> canonical -> engine -> retarget -> write.

A route reads its fields into the engine's request (files kept as the form left them,
:class:`Upload`) and calls :func:`infer`: one engine lookup (``registry.engine_for``), then
``engine.infer(request)`` in the inference pool (:mod:`service.inference`), where the engine
walks its three steps: ``prepare`` reads the uploads (:func:`load_clip`: parse, frame limit,
joint mapping, onto the canonical skeleton at 30 fps), ``predict`` runs the networks,
``finish`` post-processes and hands the canonical result to :func:`write_result` (back onto
the request's own skeleton, frame limit, BVH text). :func:`respond` answers.

Errors: a malformed BVH is a 400 problem with ``line``; a media type that is not text a
415; more than ``max_frames`` frames (in or out) a 413 with ``limit``; a skeleton that cannot
be mapped a 422 with ``unmapped``; a ``mapping`` that is not a JSON object of names a 400.
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
from service.errors import (
    InvalidRequest,
    PayloadTooLarge,
    UnsupportedMediaType,
    problem_responses,
)

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


# --- reading the request (event loop) -------------------------------------------------------


@dataclass
class Upload:
    """A file field: checked (media type, size) when the request is read, its bytes read
    when the work starts (:meth:`read`), so a request waiting for an inference slot holds
    the form's spooled file (on disk beyond 1 MB), not a copy in memory."""

    field: str
    file: UploadFile | None = None
    data: bytes | None = None  # a file sent as a plain text field
    filename: str | None = None

    def read(self) -> bytes:
        """The bytes (blocking); 400 when there is nothing but white space."""
        if self.data is not None:
            data = self.data
        else:
            assert self.file is not None
            self.file.file.seek(0)
            data = self.file.file.read()
        if not data.strip():
            raise InvalidRequest(f"'{self.field}' is empty", field=self.field)
        return data


def upload(
    file: UploadFile,
    settings: Settings,
    *,
    field: str = "content",
    accept: tuple[str, ...] = TEXT_TYPES,
    what: str = "a BVH text file",
) -> Upload:
    """An uploaded file as an :class:`Upload`: 415 when its media type starts with none of
    ``accept`` (``'<field>' must be <what>``), 413 over ``max_upload_bytes`` (the middleware
    usually stops it first), 400 when empty."""
    media = (file.content_type or "").split(";")[0].strip().lower()
    if media and not media.startswith(accept):
        raise UnsupportedMediaType(
            f"'{field}' must be {what}, got media type {media!r}", field=field
        )
    size = file.size
    if size is None:
        file.file.seek(0, 2)
        size = file.file.tell()
    if size > settings.max_upload_bytes:
        raise upload_too_large(field, settings)
    if size == 0:
        raise InvalidRequest(f"'{field}' is empty", field=field)
    return Upload(field, file=file, filename=file.filename)


def text_upload(text: str, settings: Settings, *, field: str) -> Upload:
    """A file sent as a plain form field (BVH text)."""
    data = text.encode()
    if len(data) > settings.max_upload_bytes:
        raise upload_too_large(field, settings)
    return Upload(field, data=data)


def upload_too_large(field: str, settings: Settings) -> PayloadTooLarge:
    return PayloadTooLarge(
        f"'{field}' is over {settings.max_upload_bytes} bytes",
        limit=settings.max_upload_bytes,
        limit_name="max_upload_bytes",
    )


def parse_mapping(text: str | None, field: str = "mapping") -> dict[str, str] | None:
    """An optional joint-name map field: a JSON object of joint names (either way round);
    400 naming ``field`` when it is not one."""
    if text is None or not text.strip():
        return None
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise InvalidRequest(f"'{field}' is not JSON: {exc}", field=field) from None
    if not isinstance(value, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in value.items()
    ):
        raise InvalidRequest(f"'{field}' must be a JSON object of joint names", field=field)
    return value


async def infer(request: Request, family: str, job: Any) -> Any:
    """The data plane: the engine of ``family`` that takes ``job`` (one lookup, one readiness
    rule: ``registry.engine_for``), then ``engine.infer(job)`` in the inference pool."""
    engine = request.app.state.registry.engine_for(family, job)
    return await request.app.state.runner.run(engine.infer, job)


# --- inside the inference pool (blocking) ---------------------------------------------------


@dataclass
class Clip:
    """An uploaded clip: as sent (``original``), its rig, and on the canonical skeleton at
    30 fps (``canonical``)."""

    original: Motion
    rig: retarget.Rig
    canonical: Motion


def load_clip(
    source: Upload,
    settings: Settings,
    timer: metrics.StageTimer,
    *,
    mapping: dict[str, str] | None = None,
    prefix: str = "",
) -> Clip:
    """Read (400 when empty), parse (400 with ``line``), check frames (413 with ``limit``),
    map the skeleton (422 with ``unmapped``) and retarget to canonical at 30 fps. Stages are
    timed as ``<prefix>parse`` and ``<prefix>retarget``."""
    what = source.field
    with timer.stage(prefix + "parse"):
        original = bvh.loads(source.read())
    limits.check_frames(original, settings, what=what)
    with timer.stage(prefix + "retarget"):
        rig = retarget.make_rig(original.skeleton, original, mapping=mapping)
        canonical = retarget.to_canonical(original, rig, fps=C.FPS)
    limits.check_frames(canonical, settings, what=what)
    return Clip(original, rig, canonical)


@dataclass
class Result:
    """A finished request: BVH text, its frames and rate, warnings, and (set by
    ``Engine.infer``) the model and the stage timings."""

    bvh: str
    frames: int
    fps: float
    warnings: list[str] = field(default_factory=list)
    suffix: str = "styled"  # of the download's file name
    rig: dict | None = None  # the request skeleton's mapping, how it was found, confidence
    model: tuple[str, str] = ("", "")
    timer: metrics.StageTimer | None = None


def write_result(
    clip: Clip | None,
    canon: Motion,
    settings: Settings,
    timer: metrics.StageTimer,
    *,
    warnings: list[str] | tuple[str, ...] = (),
    suffix: str = "styled",
    fps: float | None = None,
) -> Result:
    """The canonical result back on the clip's own skeleton (its names, offsets, channels
    and frame rate, frame for frame with ``clip.original``), or left canonical without a
    clip; at ``fps`` when given; 413 over ``max_frames``; BVH text."""
    if clip is not None:
        with timer.stage("retarget_back"):
            out = retarget.from_canonical(canon, clip.rig, like=clip.original)
    else:
        out = canon
    if fps is not None:
        out = out.replace(fps=float(fps))
    limits.check_frames(out, settings, what="result")
    with timer.stage("write"):
        text = bvh.dumps(out)
    rig = clip.rig.report() if clip is not None else None
    return Result(text, out.num_frames, float(out.fps), list(warnings), suffix, rig)


# --- answering (event loop) -----------------------------------------------------------------


def _filename(upload_name: str | None, suffix: str) -> str:
    stem = PurePath(upload_name or "motion").stem or "motion"
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem)[:80] or "motion"
    return f"{stem}_{re.sub(r'[^A-Za-z0-9._-]+', '_', suffix)}.bvh"


def timing_headers(result: Any) -> dict[str, str]:
    """``X-Model-Version`` and ``Server-Timing`` of an engine's result."""
    name, version = result.model
    return {
        "X-Model-Version": f"{name}/{version}",
        "Server-Timing": result.timer.server_timing() if result.timer else "",
    }


def timings_ms(result: Any) -> dict[str, float]:
    return {k: round(v, 2) for k, v in (result.timer.ms if result.timer else {}).items()}


def respond(
    request: Request,
    result: Result,
    *,
    fmt: Format = "bvh",
    upload_name: str | None = None,
) -> Response:
    """The BVH as ``text/plain`` attachment with ``X-Model-Version``, ``X-Frames``, ``X-Fps``
    and ``Server-Timing`` (``X-Request-Id`` is the middleware's), or with ``fmt="json"`` the
    object ``{"bvh", "frames", "fps", "model", "timings_ms", "warnings"}`` (same headers)."""
    route = request.scope.get("route")
    endpoint = getattr(route, "path", None) or request.scope.get("path", "")
    name, version = result.model
    metrics.count_frames(endpoint, name, result.frames)
    headers = {
        **timing_headers(result),
        "X-Frames": str(result.frames),
        "X-Fps": f"{result.fps:g}",
    }
    if fmt == "json":
        body = {
            "bvh": result.bvh,
            "frames": result.frames,
            "fps": result.fps,
            "model": {"name": name, "version": version},
            "timings_ms": timings_ms(result),
            "warnings": result.warnings,
        }
        if result.rig is not None:
            body["rig"] = result.rig
        return JSONResponse(body, headers=headers)
    filename = _filename(upload_name, result.suffix)
    headers["Content-Disposition"] = f'attachment; filename="{filename}"'
    return Response(result.bvh, media_type=BVH_MEDIA_TYPE, headers=headers)

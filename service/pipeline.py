"""The one-way path of a request: parse -> canonical -> engine -> retarget -> write.

A route reads its fields into the engine's request (files kept as the form left them,
:class:`Upload`) and calls :func:`infer`: one engine lookup (``registry.engine_for``), then
``engine.infer(request)`` in the inference pool (:mod:`service.inference`), where the engine
walks its three steps: ``prepare`` reads the uploads (:func:`load_clip`: parse, frame limit,
joint mapping, onto the canonical skeleton at 30 fps), ``predict`` runs the networks,
``finish`` post-processes and hands the canonical result to :func:`write_result` (back onto
the request's own skeleton, frame limit, BVH text or GLB bytes). :func:`respond` answers.

A clip is BVH or glTF (a ``.glb``, or ``.gltf`` with embedded buffers), told apart by its
bytes (:func:`motion.gltf.is_gltf`), whatever media type it came with. The answer comes in
the clip's format unless ``?format=`` asks for another (:func:`answer_format`): a GLB answer
is the file that was sent with the new animation in place of its old one
(:meth:`motion.gltf.GltfFile.write`); ``json`` carries the result as BVH text on the rig that
was read.

Errors: a malformed BVH is a 400 problem with ``line``, a malformed glTF a 400; a media type
that is neither text nor glTF a 415; more than ``max_frames`` frames (in or out) a 413 with
``limit``; a skeleton that cannot be mapped a 422 with ``unmapped``; a ``mapping`` that is
not a JSON object of names a 400; ``format=glb`` without a glTF file to write into a 400.
"""

from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any, Literal

from fastapi import Request, UploadFile
from fastapi.responses import JSONResponse, Response

from motion import bvh, gltf, retarget
from motion import canonical as C
from motion.errors import MotionError
from motion.features import time_warp
from motion.skeleton import Motion
from service import limits, metrics
from service.config import Settings
from service.errors import (
    InvalidRequest,
    PayloadTooLarge,
    UnsupportedMediaType,
    problem_responses,
)

Format = Literal["bvh", "glb", "json"]
FORMAT_DOC = (
    "answer format; default the clip's own (BVH or GLB). glb needs a glTF clip to write "
    "into; json gives the result as BVH text with frames, rate, model, timings, warnings, rig"
)

# Media types a BVH upload may carry (clients label text files in many ways).
TEXT_TYPES = ("text/", "application/octet-stream", "application/x-bvh", "application/bvh")
# ... and a clip, which may be glTF (the bytes decide which)
CLIP_TYPES = (*TEXT_TYPES, "model/gltf-binary", "model/gltf+json", "application/json")
CLIP_WHAT = "a BVH or glTF (.glb) file"
BVH_MEDIA_TYPE = "text/plain; charset=utf-8"
GLB_MEDIA_TYPE = "model/gltf-binary"


def bvh_responses(description: str) -> dict:
    """OpenAPI ``responses`` of a route that answers BVH or GLB (or JSON with
    ``?format=json``)."""
    return {
        200: {
            "content": {"text/plain": {}, GLB_MEDIA_TYPE: {}, "application/json": {}},
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
    accept: tuple[str, ...] = CLIP_TYPES,
    what: str = CLIP_WHAT,
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
    30 fps (``canonical``); for a glTF file the parsed file (``gltf``, to write the answer
    into); the format the answer is written in (``answer``: bvh, glb or json)."""

    original: Motion
    rig: retarget.Rig
    canonical: Motion
    gltf: gltf.GltfFile | None = None
    answer: str = "bvh"

    @property
    def format(self) -> str:
        """The clip's own format: ``glb`` for a glTF file (GLB or embedded .gltf), else
        ``bvh``."""
        return "bvh" if self.gltf is None else "glb"


def answer_format(clip_format: str | None, requested: str | None) -> str:
    """The format an answer is written in: ``requested`` (``?format=``), else the clip's own
    format (``clip_format``: bvh or glb), BVH without a clip (None). ``glb`` needs a glTF
    clip to carry the animation (a BVH has no mesh or skin to put it in): 400 otherwise."""
    if requested is None:
        return clip_format or "bvh"
    if requested == "glb" and clip_format != "glb":
        what = "no glTF file was sent" if clip_format is None else "the clip is BVH"
        raise InvalidRequest(
            f"format=glb writes the new animation into the glTF file sent, and {what}: send "
            "the character as .glb (or .gltf with embedded buffers), or ask for bvh or json",
            field="format",
        )
    return requested


def read_motion(
    source: Upload, settings: Settings, *, rest_if_unanimated: bool = False
) -> tuple[Motion, gltf.GltfFile | None]:
    """The motion of an upload, BVH or glTF as its bytes say, and the parsed glTF file (None
    for a BVH). A glTF animation over ``max_frames`` is refused before it is sampled (413);
    with ``rest_if_unanimated`` a glTF rig without animation reads as its rest pose."""
    data = source.read()
    if not gltf.is_gltf(data):
        return bvh.loads(data), None
    try:
        parsed = gltf.read(
            data, max_frames=settings.max_frames, rest_if_unanimated=rest_if_unanimated
        )
    except MotionError as exc:
        if exc.kind != "too-large":
            raise
        raise PayloadTooLarge(
            f"'{source.field}': {exc.message} (max_frames)",
            limit=settings.max_frames,
            limit_name="max_frames",
        ) from None
    return parsed.motion, parsed


def load_clip(
    source: Upload,
    settings: Settings,
    timer: metrics.StageTimer,
    *,
    mapping: dict[str, str] | None = None,
    prefix: str = "",
    answer: str | None = None,
    rest_if_unanimated: bool = False,
) -> Clip:
    """Read (400 when empty), parse BVH or glTF (400, with ``line`` for BVH), check frames
    (413 with ``limit``), check the ``answer`` format asked for (:func:`answer_format`, 400),
    map the skeleton (422 with ``unmapped``) and retarget to canonical at 30 fps. Stages are
    timed as ``<prefix>parse`` and ``<prefix>retarget``."""
    what = source.field
    with timer.stage(prefix + "parse"):
        original, parsed = read_motion(source, settings, rest_if_unanimated=rest_if_unanimated)
    limits.check_frames(original, settings, what=what)
    answer = answer_format("bvh" if parsed is None else "glb", answer)
    with timer.stage(prefix + "retarget"):
        rig = retarget.make_rig(original.skeleton, original, mapping=mapping)
        canonical = retarget.to_canonical(original, rig, fps=C.FPS)
    limits.check_frames(canonical, settings, what=what)
    return Clip(original, rig, canonical, parsed, answer)


@dataclass
class Result:
    """A finished request: the answer's ``format`` (bvh, glb or json) and its body (``bvh``
    text for bvh and json, ``glb`` bytes), frames and rate, warnings, the format of the
    clip it is on (``source_format``), and (set by ``Engine.infer``) the model and the stage
    timings."""

    bvh: str
    frames: int
    fps: float
    warnings: list[str] = field(default_factory=list)
    suffix: str = "styled"  # of the download's file name
    rig: dict | None = None  # the request skeleton's mapping, how it was found, confidence
    model: tuple[str, str] = ("", "")
    timer: metrics.StageTimer | None = None
    format: str = "bvh"
    glb: bytes | None = None
    source_format: str = "bvh"


def write_result(
    clip: Clip | None,
    canon: Motion,
    settings: Settings,
    timer: metrics.StageTimer,
    *,
    warnings: list[str] | tuple[str, ...] = (),
    suffix: str = "styled",
    fps: float | None = None,
    like_clip: bool = True,
    fmt: str | None = None,
    warp: float = 1.0,
) -> Result:
    """The canonical result back on the clip's own skeleton (its names, offsets, channels
    and, with ``like_clip``, frame rate, frame for frame with ``clip.original``, played
    ``warp`` times as fast as sent when the result was time-warped, so that the joints the
    canonical skeleton lacks follow the new timing; else at the canonical motion's timing),
    or left canonical without a clip; at ``fps`` when given; 413 over ``max_frames``.
    Written in ``clip.answer`` (the format ``fmt`` for no clip): BVH text, or the clip's
    glTF file with the result as its animation."""
    answer = clip.answer if clip is not None else answer_format(None, fmt)
    if clip is not None and warp != 1.0:
        with timer.stage("time_warp"):
            original = time_warp(clip.original, warp)
        limits.check_frames(original, settings, what="result")
        clip = dataclasses.replace(clip, original=original)
    if clip is not None:
        with timer.stage("retarget_back"):
            out = retarget.from_canonical(
                canon, clip.rig, like=clip.original if like_clip else None
            )
    else:
        out = canon
    if fps is not None:
        out = out.replace(fps=float(fps))
    limits.check_frames(out, settings, what="result")
    text, glb = "", None
    with timer.stage("write"):
        if answer == "glb":
            glb = clip.gltf.write(out)
        else:
            text = bvh.dumps(out)
    rig = clip.rig.report() if clip is not None else None
    source = clip.format if clip is not None else "bvh"
    return Result(text, out.num_frames, float(out.fps), list(warnings), suffix, rig,
                  format=answer, glb=glb, source_format=source)  # fmt: skip


# --- answering (event loop) -----------------------------------------------------------------


def _filename(upload_name: str | None, suffix: str, extension: str = "bvh") -> str:
    stem = PurePath(upload_name or "motion").stem or "motion"
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", stem)[:80] or "motion"
    return f"{stem}_{re.sub(r'[^A-Za-z0-9._-]+', '_', suffix)}.{extension}"


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
    upload_name: str | None = None,
) -> Response:
    """The answer in ``result.format``: BVH as a ``text/plain`` attachment, or GLB as a
    ``model/gltf-binary`` one, with ``X-Model-Version``, ``X-Frames``, ``X-Fps`` and
    ``Server-Timing`` (``X-Request-Id`` is the middleware's); or for ``json`` the object
    ``{"bvh", "frames", "fps", "model", "timings_ms", "warnings", "source_format"}`` (and
    ``rig``; same headers)."""
    route = request.scope.get("route")
    endpoint = getattr(route, "path", None) or request.scope.get("path", "")
    name, version = result.model
    metrics.count_frames(endpoint, name, result.frames)
    headers = {
        **timing_headers(result),
        "X-Frames": str(result.frames),
        "X-Fps": f"{result.fps:g}",
    }
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
        return JSONResponse(body, headers=headers)
    if result.format == "glb":
        filename = _filename(upload_name, result.suffix, "glb")
        headers["Content-Disposition"] = f'attachment; filename="{filename}"'
        return Response(result.glb, media_type=GLB_MEDIA_TYPE, headers=headers)
    filename = _filename(upload_name, result.suffix)
    headers["Content-Disposition"] = f'attachment; filename="{filename}"'
    return Response(result.bvh, media_type=BVH_MEDIA_TYPE, headers=headers)

"""The engines' clip toolkit: an upload in, onto the canonical skeleton, and the canonical
result back onto the request's own skeleton and format. No HTTP here: the routes hand
:class:`Upload` objects over, the engines call :func:`load_clip` in ``prepare`` and
:func:`write_result` in ``finish`` (both blocking: the inference pool runs them).

A clip is BVH or glTF (a ``.glb``, or ``.gltf`` with embedded buffers), told apart by its
bytes (:func:`motion.gltf.is_gltf`), whatever media type it came with. The answer comes in
the clip's format unless ``?format=`` asks for another (:func:`answer_format`): a GLB answer
is the file that was sent with the new animation in place of its old one
(:meth:`motion.gltf.GltfFile.write`); ``json`` carries the result as BVH text on the rig that
was read.

Errors: a malformed BVH is a 400 problem with ``line``, a malformed glTF a 400; more than
``max_frames`` frames (in or out) a 413 with ``limit``; a skeleton that cannot be mapped a
422 with ``unmapped``; ``format=glb`` without a glTF file to write into a 400.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import BinaryIO, Literal

from motion import bvh, gltf, retarget
from motion import canonical as C
from motion.errors import MotionError
from motion.features import time_warp
from motion.skeleton import Motion
from service import limits, metrics
from service.config import Settings
from service.errors import InvalidRequest, PayloadTooLarge

Format = Literal["bvh", "glb", "json"]


@dataclass
class Upload:
    """A file field, checked (media type, size) when the request was read, its bytes read
    when the work starts (:meth:`read`), so a request waiting for an inference slot holds
    the form's spooled file (on disk beyond 1 MB), not a copy in memory."""

    field: str
    file: BinaryIO | None = None
    data: bytes | None = None  # a file sent as a plain text field
    filename: str | None = None

    def read(self) -> bytes:
        """The bytes (blocking); 400 when there is nothing but white space."""
        if self.data is not None:
            data = self.data
        else:
            assert self.file is not None
            self.file.seek(0)
            data = self.file.read()
        if not data.strip():
            raise InvalidRequest(f"'{self.field}' is empty", field=self.field)
        return data


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
    clip it is on (``source_format``), and (set by the data plane) the model and the stage
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


def name_the_clip(exc: Exception, what: str) -> None:
    """Put ``what`` (which clip) in front of a problem's message, so a client knows which
    of its clips was refused."""
    if hasattr(exc, "message") and isinstance(exc.message, str):  # MotionError
        exc.message = f"{what}: {exc.message}"
        exc.args = (exc.message,)
    elif hasattr(exc, "detail") and isinstance(exc.detail, str):  # ServiceError
        exc.detail = f"{what}: {exc.detail}"

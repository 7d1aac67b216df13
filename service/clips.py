"""The engines' clip toolkit: an upload in, onto the canonical skeleton, and the canonical
result back onto the request's own skeleton and format. No HTTP here: the routes hand
:class:`Upload` objects over, the engines call :func:`load_clip` in ``prepare`` and
:func:`write_result` in ``finish`` (both blocking: the inference pool runs them).

A clip is BVH, glTF (a ``.glb``, or ``.gltf`` with embedded buffers) or FBX (with the
``fbx`` extra: :mod:`service.fbx`), told apart by its bytes (:func:`motion.gltf.is_gltf`,
:func:`service.fbx.is_fbx`), whatever media type it came with. The answer comes in the clip's
format unless ``?format=`` asks for another (:func:`answer_format`): a GLB or FBX answer is
the file that was sent with the new animation in place of its old one
(:meth:`motion.gltf.GltfFile.write`, :meth:`service.fbx.FbxFile.write`); ``json`` carries the
result as BVH text on the rig that was read.

Game invariants (:class:`GameOptions`, for a clip to restyle): leading reference frames (a
bind or T-pose before the motion, :mod:`motion.reference`) are cut off before the clip goes
onto the canonical skeleton and put back unchanged in front of the answer, with a warning; a
looping clip (:mod:`motion.loops`: found, or ``loop=true``; ``loop=false`` looks for none)
goes on as a closed cycle (an open one gains its first frame at the end, taken off the
answer again) resampled to 30 fps end to end, so the engines can wrap it around and its
answer ends where it starts; ``root_motion=in_place`` takes the hips' travel on the floor
out of the answer (:mod:`motion.root_motion`).

Errors: a malformed BVH is a 400 problem with ``line``, a malformed glTF a 400; more than
``max_frames`` frames (in or out) a 413 with ``limit``; a skeleton that cannot be mapped a
422 with ``unmapped``; ``format=glb`` (``fbx``) without a glTF (FBX) file to write into a
400; an FBX where the ``fbx`` extra is not installed a 415 saying how to enable it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import BinaryIO, Literal

import numpy as np

from motion import bvh, gltf, loops, retarget
from motion import canonical as C
from motion import kinematics as K
from motion.anatomy import Warp
from motion.errors import MotionError
from motion.reference import leading_reference_frames, rest_on_canonical
from motion.root_motion import in_place
from motion.skeleton import Motion
from service import fbx, limits, metrics
from service.config import Settings
from service.errors import InvalidRequest, PayloadTooLarge

Format = Literal["bvh", "glb", "fbx", "json"]
LoopMode = Literal["auto", "true", "false"]
RootMotion = Literal["keep", "in_place"]


@dataclass(frozen=True)
class GameOptions:
    """What a game asks of a restyled clip: ``loop`` (auto: found from the clip, true: it
    loops, false: it does not) and ``root_motion`` (keep, or in_place)."""

    loop: LoopMode = "auto"
    root_motion: RootMotion = "keep"


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
    30 fps (``canonical``); for a glTF or FBX file the parsed file (``file``, to write the
    answer into); the format the answer is written in (``answer``: bvh, glb, fbx or json)."""

    original: Motion
    rig: retarget.Rig
    canonical: Motion
    file: gltf.GltfFile | fbx.FbxFile | None = None
    answer: str = "bvh"
    reference: Motion | None = None  # leading reference frames, cut off ``original``
    loop: loops.Loop | None = None  # a cycle: ``canonical`` is closed, 30 fps end to end
    closing: bool = False  # ``original`` (an open cycle) gained its first frame at the end
    root_motion: RootMotion = "keep"
    warnings: list[str] = field(default_factory=list)

    @property
    def format(self) -> str:
        """The clip's own format: ``glb`` for a glTF file (GLB or embedded .gltf), ``fbx``
        for an FBX, else ``bvh``."""
        return file_format(self.file)


def file_format(parsed: gltf.GltfFile | fbx.FbxFile | None) -> str:
    if parsed is None:
        return "bvh"
    return "fbx" if isinstance(parsed, fbx.FbxFile) else "glb"


FILE_FORMATS = {"glb": "glTF", "fbx": "FBX"}  # formats written into the file sent
_FORMAT_NAMES = {"bvh": "BVH", **FILE_FORMATS}


def answer_format(clip_format: str | None, requested: str | None) -> str:
    """The format an answer is written in: ``requested`` (``?format=``), else the clip's own
    format (``clip_format``: bvh, glb or fbx), BVH without a clip (None). ``glb`` and ``fbx``
    need a clip of that format to carry the animation (a BVH has no mesh or skin to put it
    in, and one format is not converted into the other): 400 otherwise."""
    if requested is None:
        return clip_format or "bvh"
    if requested in FILE_FORMATS and clip_format != requested:
        kind = FILE_FORMATS[requested]
        what = (
            f"no {kind} file was sent"
            if clip_format is None
            else f"the clip is {_FORMAT_NAMES[clip_format]}"
        )
        send = "as .glb (or .gltf with embedded buffers)" if requested == "glb" else "as .fbx"
        raise InvalidRequest(
            f"format={requested} writes the new animation into the {kind} file sent, and "
            f"{what}: send the character {send}, or ask for bvh or json",
            field="format",
        )
    return requested


def read_motion(
    source: Upload, settings: Settings, *, rest_if_unanimated: bool = False
) -> tuple[Motion, gltf.GltfFile | fbx.FbxFile | None]:
    """The motion of an upload, BVH, glTF or FBX as its bytes say, and the parsed glTF or
    FBX file (None for a BVH). An animation over ``max_frames`` is refused before it is
    sampled (413); with ``rest_if_unanimated`` a rig without animation reads as its rest
    pose."""
    data = source.read()
    try:
        if fbx.is_fbx(data):
            parsed = fbx.read(
                data,
                workers=settings.fbx_workers,
                timeout=settings.request_timeout_s,
                max_frames=settings.max_frames,
                rest_if_unanimated=rest_if_unanimated,
            )
        elif gltf.is_gltf(data):
            parsed = gltf.read(
                data, max_frames=settings.max_frames, rest_if_unanimated=rest_if_unanimated
            )
        else:
            return bvh.loads(data), None
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
    game: GameOptions | None = None,
) -> Clip:
    """Read (400 when empty), parse BVH or glTF (400, with ``line`` for BVH), check frames
    (413 with ``limit``), check the ``answer`` format asked for (:func:`answer_format`, 400),
    map the skeleton (422 with ``unmapped``) and retarget to canonical at 30 fps; with
    ``game`` (a clip to restyle) its reference frames and loop as the module docstring
    says. Stages are timed as ``<prefix>parse`` and ``<prefix>retarget``."""
    what = source.field
    with timer.stage(prefix + "parse"):
        original, parsed = read_motion(source, settings, rest_if_unanimated=rest_if_unanimated)
    limits.check_frames(original, settings, what=what)
    answer = answer_format(file_format(parsed), answer)
    with timer.stage(prefix + "retarget"):
        rig = retarget.make_rig(original.skeleton, original, mapping=mapping)
        if game is None:
            clip = Clip(original, rig, retarget.to_canonical(original, rig, fps=C.FPS), parsed)
        else:
            clip = game_clip(original, rig, game, parsed)
    limits.check_frames(clip.canonical, settings, what=what)
    clip.answer = answer
    return clip


def game_clip(
    original: Motion,
    rig: retarget.Rig,
    game: GameOptions,
    parsed: gltf.GltfFile | fbx.FbxFile | None,
) -> Clip:
    """A clip to restyle: leading reference frames cut off, a cycle closed (module
    docstring)."""
    full = retarget.to_canonical(original, rig, fps=None)
    warnings = []
    count = leading_reference_frames(full, rest_on_canonical(rig, original.fps))
    reference = original.slice(0, count) if count else None
    if count:
        original, full = original.slice(count), full.slice(count)
        warnings.append(
            f"the first {'frame is a reference pose' if count == 1 else f'{count} frames are reference poses'} "
            "(bind or T-pose, then a jump to the motion): given back unchanged, not restyled"
        )
    loop = None if game.loop == "false" else loops.detect(full, force=game.loop == "true")
    closing = loop is not None and not loop.closed
    if closing:
        full = loops.closed(full, loop)
        original = loops.with_closing_frame(original, rig.up)
    if loop is None:
        canonical = K.resample(full, C.FPS)
    else:  # the cycle's ends stay its ends at 30 fps
        steps = max(int(round((full.num_frames - 1) * C.FPS / full.fps)), 2)
        canonical = K.resample_at(full, np.linspace(0, full.num_frames - 1, steps + 1), C.FPS)
    return Clip(original, rig, canonical, parsed, reference=reference, loop=loop,
                closing=closing, root_motion=game.root_motion, warnings=warnings)  # fmt: skip


@dataclass
class Result:
    """A finished request: the answer's ``format`` (bvh, glb, fbx or json) and its body
    (``bvh`` text for bvh and json, ``binary`` GLB or FBX bytes), frames and rate, warnings,
    the format of the
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
    binary: bytes | None = None
    source_format: str = "bvh"
    loop: bool | None = None  # whether the clip was taken as a loop (None: no clip to say)
    dance: dict | None = None  # a dance's genre, tempo and beat alignment (None: not a dance)


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
    warp: Warp | None = None,
) -> Result:
    """The canonical result back on the clip's own skeleton (its names, offsets, channels
    and, with ``like_clip``, frame rate, frame for frame with ``clip.original``, played
    along ``warp`` when the result was time-warped, so that the joints the
    canonical skeleton lacks follow the new timing; else at the canonical motion's timing),
    or left canonical without a clip; at ``fps`` when given; 413 over ``max_frames``.
    Written in ``clip.answer`` (the format ``fmt`` for no clip): BVH text, or the clip's
    glTF or FBX file with the result as its animation."""
    answer = clip.answer if clip is not None else answer_format(None, fmt)
    if clip is not None and warp is not None and not warp.identity:
        with timer.stage("time_warp"):
            original = warp.apply(clip.original)
        limits.check_frames(original, settings, what="result")
        clip = dataclasses.replace(clip, original=original)
    if clip is not None:
        with timer.stage("retarget_back"):
            like = clip.original if like_clip else None
            if clip.loop is not None and like is not None:  # end to end, as the cycle went in
                times = np.linspace(0, canon.num_frames - 1, like.num_frames)
                canon = K.resample_at(canon, times, like.fps)
            out = retarget.from_canonical(canon, clip.rig, like=like)
            out = finished_on_rig(clip, out)
    else:
        out = canon
    if fps is not None:
        out = out.replace(fps=float(fps))
    limits.check_frames(out, settings, what="result")
    text, binary = "", None
    with timer.stage("write"):
        if answer in FILE_FORMATS:
            binary = clip.file.write(out)
        else:
            text = bvh.dumps(out)
    rig = clip.rig.report() if clip is not None else None
    source = clip.format if clip is not None else "bvh"
    warnings = [*(clip.warnings if clip is not None else ()), *warnings]
    loop = None if clip is None else clip.loop is not None
    return Result(text, out.num_frames, float(out.fps), warnings, suffix, rig,
                  format=answer, binary=binary, source_format=source, loop=loop)  # fmt: skip


def finished_on_rig(clip: Clip, out: Motion) -> Motion:
    """The answer on the clip's rig as the game asked: an open cycle's closing frame taken
    off, the travel taken out for ``in_place``, the reference frames put back in front."""
    if clip.closing:
        out = out.slice(0, -1)
    if clip.root_motion == "in_place":
        out = in_place(out, clip.rig.mapping["Hips"], clip.rig.up)
    if clip.reference is not None:
        reference = clip.reference
        out = out.replace(
            lrot=np.concatenate([reference.lrot, out.lrot]),
            lpos=np.concatenate([reference.lpos, out.lpos]),
        )
    return out


def name_the_clip(exc: Exception, what: str) -> None:
    """Put ``what`` (which clip) in front of a problem's message, so a client knows which
    of its clips was refused."""
    if hasattr(exc, "message") and isinstance(exc.message, str):  # MotionError
        exc.message = f"{what}: {exc.message}"
        exc.args = (exc.message,)
    elif hasattr(exc, "detail") and isinstance(exc.detail, str):  # ServiceError
        exc.detail = f"{what}: {exc.detail}"

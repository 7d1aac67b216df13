"""What the two restyling families share: the shapes their networks run at and the finish of
a restyler's output into canonical motion (the translator's restyler and the fast networks
distilled from it write the same channels, so one finish serves both).

The finish: smooth the rotations over time (a Gaussian of the bundle's ``output_smoothing``
frames, chosen per model at export by ``model_export.output_smoothing``: the least that
leaves the output no jerkier than real mocap); at a ``strength`` other than 1, each joint's
rotation goes that part of the way from the content's own to the restyled one (0 gives the
content back); the content's root trajectory (``features.decode_motion``); the feet planted
where the CONTENT's are, held on the content's floor (the knees bend to reach it down to
``grounding.KNEE_ABSORB`` of a leg, the hips move for the rest), and the feet the content
has in the air kept clear of the floor (``grounding.pin_canonical_feet``); a looping clip's
cycle, which ran wrapped around (:func:`wrapped`), cut back (:func:`anatomical`); jumps
no body makes bridged over (faster than real mocap and than the content at that step);
knees and elbows bent only the way they bend, after every clean-up step. A time warp follows,
clamped to [``MIN_WARP``, ``MAX_WARP``] and slowed where a joint would move faster than
real mocap does (:func:`speed_limited`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion import contacts as CT
from motion import features as Fe
from motion import grounding
from motion.anatomy import SPEED_LIMIT, Warp, despiked, hinged, speed_limited_warp
from motion.loops import Cycle
from motion.skeleton import Motion
from service.metrics import StageTimer

BUCKET = 64  # frames: padded lengths are multiples of this, so onnxruntime sees few shapes
MIN_WARP, MAX_WARP = 0.5, 2.0  # time warp factors are clamped to this range


def padded_length(frames: int, minimum: int = BUCKET) -> int:
    """The bucket a clip of ``frames`` frames runs at: a multiple of ``BUCKET``, >= ``minimum``."""
    return max(-(-frames // BUCKET) * BUCKET, -(-minimum // BUCKET) * BUCKET)


def pad_mirrored(x: np.ndarray, total: int) -> tuple[np.ndarray, int]:
    """``x (F, C)`` mirrored at both ends to ``total`` frames; returns it and the offset of
    frame 0 (crop ``[offset : offset + F]``)."""
    extra = total - len(x)
    before = extra // 2
    return np.pad(x, ((before, extra - before), (0, 0)), mode="symmetric"), before


def clamp_warp(factor: float) -> float:
    return min(max(factor, MIN_WARP), MAX_WARP)


def restyled_motion(
    output: np.ndarray,
    content: Motion,
    enc: Fe.Encoded,
    stats: Fe.FeatureStats,
    timer: StageTimer,
    smoothing: float,
    strength: float = 1.0,
    foot_cleanup: bool = True,
) -> Motion:
    """A restyler's standardised output ``(F, OUTPUT_CHANNELS)`` for the canonical
    ``content`` (encoded as ``enc``) -> the canonical result: smoothed over time (a Gaussian
    of ``smoothing`` frames), taken ``strength`` of the way from the content's own pose, on
    the content's root trajectory, feet on its floor (module docstring)."""
    with timer.stage("rotations"):
        output = Fe.unstandardize(output, stats, "output")
        if smoothing > 0:
            output = gaussian_filter1d(output, smoothing, axis=0, mode="nearest")
        if strength != 1.0:  # part of the way from the content's own pose, or past the output
            own = enc.content[:, : Fe.OUTPUT_CHANNELS]
            output = own + np.float32(strength) * (output - own)
        motion = Fe.decode_motion(output, content, face=enc.facing)
    if foot_cleanup:
        with timer.stage("foot_cleanup"):
            feet = enc.gpos  # the features' FK: contacts and floor read the content posed once
            contacts = CT.canonical_foot_contacts(content, positions=feet)
            motion = grounding.pin_canonical_feet(
                motion, contacts, floor_of=content, floor_positions=feet
            )
    return motion


def wrapped(content: Motion, loop: bool, margin: int) -> tuple[Motion, Cycle | None]:
    """A looping clip's canonical cycle (closed: its last frame its first moved on, as
    ``service.clips.load_clip`` makes it) with ``margin`` frames of itself before and after
    (:class:`motion.loops.Cycle`), so the networks' windows, the smoothing and the foot
    clean-up see it wrap around; anything else as it is."""
    if not loop:
        return content, None
    cycle = Cycle.of(content, margin)
    return cycle.extended(content), cycle


def anatomical(motion: Motion, cycle: Cycle | None, content: Motion) -> Motion:
    """A restyled canonical motion cut back to its cycle (when it was :func:`wrapped`),
    without jumps faster than real mocap and the ``content`` it restyles move
    (:func:`motion.anatomy.despiked`), and with its knees and elbows bent only the way they
    bend (:func:`motion.anatomy.hinged`)."""
    if cycle is not None:
        motion = cycle.cropped(motion)
    return hinged(despiked(motion, content))


def speed_limited(factor: float, motion: Motion) -> tuple[Warp, list[str]]:
    """The time warp by ``factor``, slowed where a joint of the warped ``motion`` would move
    faster than real mocap does (:func:`motion.anatomy.speed_limited_warp`), and a warning
    when it was."""
    warp = speed_limited_warp(factor, motion)
    if warp.source is None:
        return warp, []
    return warp, [
        f"time warp {factor:.3f} lowered to {warp.factor:.3f}: slowed where a joint would "
        f"move over {SPEED_LIMIT:g} body heights a second (real mocap's fastest: 6.8)"
    ]

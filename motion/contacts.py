"""Foot contacts from joint positions, and the foot-skating measure.

A foot joint is in contact when it is low (relative to the clip's own ground
level, so clips whose floor is not at y = 0 work) and its horizontal speed is
small. Thresholds default to fractions of the leg length (``scale``), so the
same clip in centimetres or in inches gets the same labels. Y is up.

Shapes: ``gpos (F, J, 3)`` global joint positions, contacts ``(F, n)`` bool for
``n`` foot joints.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from motion import canonical as C
from motion import kinematics as K
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton

# Defaults as fractions of the leg length (hip to ankle): Bandai's leg is 80 cm,
# so contact means within ~5 cm of the joint's ground level and slower than ~24 cm/s.
HEIGHT_FRACTION = 0.06
SPEED_FRACTION = 0.3  # leg lengths per second
# A foot joint's ground level is a low percentile of its height over the clip...
GROUND_PERCENTILE = 5.0
# ...but never more than this far (leg lengths) above the lowest foot joint's, so a
# foot held up for a whole clip is not "on its own ground".
MAX_GROUND_ELEVATION = 0.2
MIN_CONTACT_SECONDS = 2.0 / 30.0  # shorter contacts are dropped, shorter gaps filled
# Median vertical extent of a standing humanoid over its leg length (Bandai 1.7, CMU 1.6).
EXTENT_PER_LEG = 1.7

CANONICAL_FOOT_JOINTS = [C.INDEX[n] for n in ("Foot_L", "Toes_L", "Foot_R", "Toes_R")]


def chain_length(skeleton: Skeleton, top: int, bottom: int) -> float:
    """Sum of the bone lengths from joint ``top`` down to its descendant ``bottom``."""
    total = 0.0
    j = bottom
    while j != top:
        if j <= 0:
            raise MotionError(f"joint {bottom} is not below joint {top}", kind="unusable")
        total += float(np.linalg.norm(skeleton.offsets[j]))
        j = int(skeleton.parents[j])
    return total


def estimate_scale(gpos: np.ndarray) -> float:
    """Rough leg length from positions ``(F, J, 3)``: median vertical extent / 1.7."""
    gpos = np.asarray(gpos, dtype=np.float64)
    extent = gpos[..., 1].max(axis=-1) - gpos[..., 1].min(axis=-1)
    return max(float(np.median(extent)) / EXTENT_PER_LEG, 1e-9)


def ground_heights(
    gpos: np.ndarray, foot_joints: list[int], scale: float | None = None
) -> np.ndarray:
    """Each foot joint's height when planted ``(n,)``, from the clip itself.

    A low percentile of the joint's height, capped at ``MAX_GROUND_ELEVATION`` leg
    lengths above the lowest such level among ``foot_joints``.
    """
    gpos = np.asarray(gpos, dtype=np.float64)
    scale = estimate_scale(gpos) if scale is None else float(scale)
    heights = gpos[:, foot_joints, 1]
    levels = np.percentile(heights, GROUND_PERCENTILE, axis=0)
    return np.minimum(levels, levels.min() + MAX_GROUND_ELEVATION * scale)


def local_ground(heights: np.ndarray, fps: float, seconds: float) -> np.ndarray:
    """``(F,)``: the lowest of the feet's ``heights (F, n)`` over a sliding window of about
    ``seconds`` (an odd number of frames), for a floor that drifts within a clip, where
    :func:`ground_heights` finds one level for the whole clip."""
    window = max(1, int(round(seconds * fps)) | 1)
    return ndimage.minimum_filter1d(np.asarray(heights).min(axis=1), window, mode="nearest")


def horizontal_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """Speed on the floor (X, Z) per second, central differences: ``(F, ...)`` from ``(F, ..., 3)``."""
    positions = np.asarray(positions, dtype=np.float64)
    if len(positions) < 2:
        return np.zeros(positions.shape[:-1])
    floor = positions[..., [0, 2]]
    return np.linalg.norm(np.gradient(floor, axis=0), axis=-1) * fps


def clean_contacts(contacts: np.ndarray, min_frames: int) -> np.ndarray:
    """Contacts ``(F, n)`` with gaps shorter than ``min_frames`` filled, then shorter contacts dropped."""
    contacts = np.asarray(contacts, dtype=bool)
    if min_frames < 2 or len(contacts) == 0:
        return contacts.copy()
    structure = np.ones((min_frames, 1), dtype=bool)
    # pad with the edge values so that contacts touching the clip's ends survive
    padded = np.pad(contacts, ((min_frames, min_frames), (0, 0)), mode="edge")
    padded = ndimage.binary_closing(padded, structure=structure)
    padded = ndimage.binary_opening(padded, structure=structure)
    return padded[min_frames:-min_frames]


def foot_contacts(
    gpos: np.ndarray,
    fps: float,
    foot_joints: list[int],
    height_threshold: float | None = None,
    velocity_threshold: float | None = None,
    scale: float | None = None,
    min_seconds: float = MIN_CONTACT_SECONDS,
) -> np.ndarray:
    """Contact labels ``(F, len(foot_joints))`` bool from global positions ``gpos (F, J, 3)``.

    A joint is in contact when it is within ``height_threshold`` of its ground level
    (:func:`ground_heights`) and its horizontal speed is below ``velocity_threshold``
    (units per second). ``scale`` is the leg length (hip to ankle) in the clip's units,
    estimated from the pose when not given; the thresholds default to
    ``HEIGHT_FRACTION * scale`` and ``SPEED_FRACTION * scale`` per second. Gaps and
    contacts shorter than ``min_seconds`` (2 frames at 30 fps) are removed.
    """
    gpos = np.asarray(gpos, dtype=np.float64)
    if gpos.ndim != 3 or gpos.shape[-1] != 3:
        raise MotionError(f"positions must be (frames, joints, 3), got {gpos.shape}")
    if not np.isfinite(fps) or fps <= 0:
        raise MotionError(f"frame rate must be positive, got {fps}")
    foot_joints = list(foot_joints)
    if len(gpos) == 0 or not foot_joints:
        return np.zeros((len(gpos), len(foot_joints)), dtype=bool)
    scale = estimate_scale(gpos) if scale is None else float(scale)
    height_threshold = HEIGHT_FRACTION * scale if height_threshold is None else height_threshold
    velocity_threshold = (
        SPEED_FRACTION * scale if velocity_threshold is None else velocity_threshold
    )
    feet = gpos[:, foot_joints]
    low = feet[..., 1] - ground_heights(gpos, foot_joints, scale) < height_threshold
    slow = horizontal_speed(feet, fps) < velocity_threshold
    min_frames = max(1, int(round(min_seconds * fps)))
    return clean_contacts(low & slow, min_frames)


def canonical_foot_positions(motion: Motion) -> np.ndarray:
    """World positions ``(F, J, 3)`` of a canonical-skeleton motion with only the feet
    and the joints above them posed (the others zero): what the contacts and the floor
    read, computed once for both."""
    return K.fk(motion.lrot, motion.lpos, motion.skeleton.parents, joints=CANONICAL_FOOT_JOINTS)[1]


def canonical_foot_contacts(
    motion: Motion, positions: np.ndarray | None = None, **thresholds
) -> np.ndarray:
    """Contacts ``(F, 4)`` of Foot_L, Toes_L, Foot_R, Toes_R for a canonical-skeleton motion;
    ``positions``, when given, its :func:`canonical_foot_positions`."""
    if motion.skeleton.names != C.JOINTS:
        raise MotionError("expected a motion on the canonical skeleton", kind="unusable")
    thresholds.setdefault("scale", C.leg_length())
    if thresholds["scale"] is None:  # the scale is estimated from the whole body
        gpos = K.global_positions(motion)
    else:  # only the feet's positions are read: the rest of the body is not posed
        gpos = canonical_foot_positions(motion) if positions is None else positions
    return foot_contacts(gpos, motion.fps, CANONICAL_FOOT_JOINTS, **thresholds)


def foot_skating(
    gpos: np.ndarray,
    contacts: np.ndarray,
    fps: float,
    foot_joints: list[int],
    leg_length: float | None = None,
) -> float:
    """Mean horizontal foot speed during contact: units per second, or leg lengths per
    second when ``leg_length`` is given (comparable across skeletons).

    ``gpos (F, J, 3)``, ``contacts (F, len(foot_joints))``. The speed of a joint between
    frames t and t + 1 counts when it is in contact on both; 0.0 when there is none.
    """
    gpos = np.asarray(gpos, dtype=np.float64)
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (len(gpos), len(foot_joints)):
        raise MotionError(
            f"contacts must be ({len(gpos)}, {len(foot_joints)}), got {contacts.shape}"
        )
    if len(gpos) < 2:
        return 0.0
    feet = gpos[:, foot_joints][..., [0, 2]]
    speed = np.linalg.norm(feet[1:] - feet[:-1], axis=-1) * fps
    both = contacts[1:] & contacts[:-1]
    if not both.any():
        return 0.0
    value = float(speed[both].mean())
    return value / leg_length if leg_length else value


def canonical_foot_skating(motion: Motion, contacts: np.ndarray | None = None) -> float:
    """Foot skating in cm/s of a canonical motion (contacts detected when not given)."""
    contacts = canonical_foot_contacts(motion) if contacts is None else contacts
    gpos = K.global_positions(motion)
    return foot_skating(gpos, contacts, motion.fps, CANONICAL_FOOT_JOINTS)


def foot_sliding(
    gpos: np.ndarray, fps: float, foot_joints: list[int], height: float, scale: float | None = None
) -> float:
    """Foot sliding as Zhang et al. (2018, mode-adaptive networks) measure it: each foot
    joint's horizontal speed weighted by ``2 - 2 ** (h / height)`` while its height ``h``
    over its ground level (:func:`ground_heights`) is below ``height``, averaged over frames
    and joints; units per second.

    It needs no contact labels (so a generated clip is judged like a real one) and counts
    a foot fully only when it is on the floor, partly as it lifts.
    """
    gpos = np.asarray(gpos, dtype=np.float64)
    if gpos.ndim != 3 or gpos.shape[-1] != 3:
        raise MotionError(f"positions must be (frames, joints, 3), got {gpos.shape}")
    if len(gpos) < 2 or not foot_joints:
        return 0.0
    feet = gpos[:, list(foot_joints)]
    h = feet[..., 1] - ground_heights(gpos, list(foot_joints), scale)
    weight = np.clip(2.0 - np.exp2(np.maximum(h, 0.0) / height), 0.0, 1.0)
    return float((horizontal_speed(feet, fps) * weight).mean())


def canonical_foot_sliding(motion: Motion, height: float = 2.5) -> float:
    """:func:`foot_sliding` in cm/s of a canonical motion (feet and toes), ``height`` in cm."""
    if motion.skeleton.names != C.JOINTS:
        raise MotionError("expected a motion on the canonical skeleton", kind="unusable")
    gpos = K.global_positions(motion)
    return foot_sliding(gpos, motion.fps, CANONICAL_FOOT_JOINTS, height, scale=C.leg_length())

"""Pose detectors' keypoint layouts (OpenPose BODY_25 and COCO-18, COCO-17, MediaPipe
Pose 33) and how each maps onto the canonical joints.

Joints a layout does not observe (Spine, Chest, Shoulder_L/R, joint_Root; Toes for COCO
layouts) are derived from those it does (:func:`to_canonical`), in proportions measured on
the Bandai data; their confidence is 0.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from motion import canonical as C
from motion.errors import MotionError

# Fractions measured on the Bandai data (median over 15 takes, global positions):
# Spine and Chest lie at 0.383 and 0.602 of the Hips->Neck segment, Shoulder_L/R at
# 0.53 of Neck->UpperArm, Head 0.157 torso lengths above the Neck. The limb lengths
# (in torso lengths, Hips->Neck) place joints that are never seen.
SPINE_FRACTION = 0.38
CHEST_FRACTION = 0.60
SHOULDER_FRACTION = 0.53
_HEAD_ABOVE_NECK = 0.16
_UPPER_ARM = 0.59
_FOREARM = 0.54
_THIGH = 0.95
_SHIN = 1.0

# Detectors mark the hip joints and the shoulder line; the canonical Hips sit above the
# hip joints, the Neck above the shoulder line and the Head at a fixed distance from the
# Neck. In lengths of the detector's torso (hip-joint midpoint to shoulder midpoint), on
# the canonical rest pose (tests check them against motion.canonical): left at the
# detector's points, the 2D style input was 5-7 standard deviations off the training
# data's for these joints (their offsets from the Hips hardly vary in 3D motion).
HIPS_ABOVE_HIP_JOINTS = 0.055
NECK_ABOVE_SHOULDERS = 0.084
HEAD_FROM_NECK = 0.162


@dataclass(frozen=True)
class Layout:
    """A detector's keypoint layout and its recipe for the canonical joints.

    ``recipe`` maps a canonical joint to alternatives, best first; an alternative is a
    tuple of source keypoint indices whose mean gives the joint.
    """

    name: str
    count: int
    recipe: dict[str, tuple[tuple[int, ...], ...]]


def _limbs(
    sh: int, el: int, wr: int, hip: int, kn: int, an: int, side: str
) -> dict[str, tuple[tuple[int, ...], ...]]:
    return {
        f"UpperArm_{side}": ((sh,),),
        f"LowerArm_{side}": ((el,),),
        f"Hand_{side}": ((wr,),),
        f"UpperLeg_{side}": ((hip,),),
        f"LowerLeg_{side}": ((kn,),),
        f"Foot_{side}": ((an,),),
    }


def _pair(a: int, b: int) -> tuple[tuple[int, ...], ...]:
    """Mid of two points, else either one."""
    return ((a, b), (a,), (b,))


# BODY_25: 0 Nose, 1 Neck, 2 RShoulder, 3 RElbow, 4 RWrist, 5 LShoulder, 6 LElbow,
# 7 LWrist, 8 MidHip, 9 RHip, 10 RKnee, 11 RAnkle, 12 LHip, 13 LKnee, 14 LAnkle, 15 REye,
# 16 LEye, 17 REar, 18 LEar, 19 LBigToe, 20 LSmallToe, 21 LHeel, 22 RBigToe, 23 RSmallToe,
# 24 RHeel.
_BODY25 = Layout(
    "openpose-body25",
    25,
    {
        "Hips": ((8,),) + _pair(9, 12),
        "Neck": ((1,),) + _pair(2, 5),
        "Head": _pair(17, 18) + _pair(15, 16) + ((0,),),
        **_limbs(5, 6, 7, 12, 13, 14, "L"),
        **_limbs(2, 3, 4, 9, 10, 11, "R"),
        "Toes_L": ((19,), (20,)),
        "Toes_R": ((22,), (23,)),
    },
)
# OpenPose COCO-18: 0 Nose, 1 Neck, 2 RShoulder, 3 RElbow, 4 RWrist, 5 LShoulder,
# 6 LElbow, 7 LWrist, 8 RHip, 9 RKnee, 10 RAnkle, 11 LHip, 12 LKnee, 13 LAnkle, 14 REye,
# 15 LEye, 16 REar, 17 LEar.
_COCO18 = Layout(
    "openpose-coco18",
    18,
    {
        "Hips": _pair(8, 11),
        "Neck": ((1,),) + _pair(2, 5),
        "Head": _pair(16, 17) + _pair(14, 15) + ((0,),),
        **_limbs(5, 6, 7, 11, 12, 13, "L"),
        **_limbs(2, 3, 4, 8, 9, 10, "R"),
    },
)
# COCO-17 (detectors): 0 nose, 1 left_eye, 2 right_eye, 3 left_ear, 4 right_ear,
# 5 left_shoulder, 6 right_shoulder, 7 left_elbow, 8 right_elbow, 9 left_wrist,
# 10 right_wrist, 11 left_hip, 12 right_hip, 13 left_knee, 14 right_knee, 15 left_ankle,
# 16 right_ankle.
_COCO17 = Layout(
    "coco17",
    17,
    {
        "Hips": _pair(11, 12),
        "Neck": _pair(5, 6),
        "Head": _pair(3, 4) + _pair(1, 2) + ((0,),),
        **_limbs(5, 7, 9, 11, 13, 15, "L"),
        **_limbs(6, 8, 10, 12, 14, 16, "R"),
    },
)
# MediaPipe Pose (BlazePose) 33: 0 nose, 1-3 left eye inner/eye/outer, 4-6 right eye,
# 7 left_ear, 8 right_ear, 9-10 mouth, 11 left_shoulder, 12 right_shoulder, 13/14 elbows,
# 15/16 wrists, 17-22 pinky/index/thumb, 23/24 hips, 25/26 knees, 27/28 ankles,
# 29/30 heels, 31 left_foot_index, 32 right_foot_index (left first in each pair).
_MEDIAPIPE33 = Layout(
    "mediapipe-pose33",
    33,
    {
        "Hips": _pair(23, 24),
        "Neck": _pair(11, 12),
        "Head": _pair(7, 8) + _pair(2, 5) + ((0,),),
        **_limbs(11, 13, 15, 23, 25, 27, "L"),
        **_limbs(12, 14, 16, 24, 26, 28, "R"),
        "Toes_L": ((31,),),
        "Toes_R": ((32,),),
    },
)
LAYOUTS: dict[str, Layout] = {lay.name: lay for lay in (_BODY25, _COCO18, _COCO17, _MEDIAPIPE33)}
BY_COUNT = {lay.count: lay for lay in LAYOUTS.values()}
_ALIASES = {
    "openposebody25": "openpose-body25",
    "body25": "openpose-body25",
    "openpose": "openpose-body25",
    "openposecoco18": "openpose-coco18",
    "openposecoco": "openpose-coco18",
    "coco18": "openpose-coco18",
    "coco17": "coco17",
    "coco": "coco17",
    "mediapipepose33": "mediapipe-pose33",
    "mediapipe33": "mediapipe-pose33",
    "mediapipepose": "mediapipe-pose33",
    "mediapipe": "mediapipe-pose33",
    "blazepose": "mediapipe-pose33",
    "blazepose33": "mediapipe-pose33",
}


def resolve_layout(name: Any) -> Layout | None:
    if name is None:
        return None
    if not isinstance(name, str):
        raise MotionError(f"layout must be a name, got {name!r:.80}")
    key = _ALIASES.get(re.sub(r"[^a-z0-9]", "", name.lower()))
    if key is None:
        raise MotionError(
            f"unknown keypoint layout {name!r:.80}; known: {', '.join(LAYOUTS)}", kind="unsupported"
        )
    return LAYOUTS[key]


def detect_layout(frames: list[list[np.ndarray]], lay: Layout | None) -> Layout:
    counts = {p.shape[0] for people in frames for p in people}
    if lay is not None:
        wrong = counts - {lay.count}
        if wrong:
            raise MotionError(
                f"layout {lay.name} has {lay.count} keypoints, the input has {min(wrong)}"
            )
        return lay
    if not counts:
        raise MotionError("no person detected in any frame", kind="unusable")
    if len(counts) > 1:
        raise MotionError(f"frames disagree on the number of keypoints ({sorted(counts)})")
    (count,) = counts
    if count not in BY_COUNT:
        known = ", ".join(f"{c} ({x.name})" for c, x in sorted(BY_COUNT.items()))
        raise MotionError(
            f"{count} keypoints per person match no known layout; known: {known}",
            kind="unsupported",
        )
    return BY_COUNT[count]


def to_canonical(
    filled: np.ndarray,
    conf: np.ndarray,
    seen: np.ndarray,
    present: np.ndarray,
    lay: Layout,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical ``positions (F, 22, 2)`` (image y down), ``confidence (F, 22)``,
    ``observed (22,)`` from filled source points ``(F, K, 2)`` and confidences ``(F, K)``.

    For each joint the first alternative of the recipe whose points are all seen in at
    least half of the frames with a person is used, else the first whose points are all
    seen at all; joints left without one are derived by ``_derive``.
    """
    num = filled.shape[0]
    n = len(C.JOINTS)
    pos = np.zeros((num, n, 2))
    cf = np.zeros((num, n))
    observed = np.zeros(n, dtype=bool)
    have = np.zeros(n, dtype=bool)
    need = 0.5 * int(present.sum())
    for name, alternatives in lay.recipe.items():
        j = C.INDEX[name]
        observed[j] = True
        pick = next((a for a in alternatives if all(seen[i] >= need for i in a)), None)
        if pick is None:
            pick = next((a for a in alternatives if all(seen[i] > 0 for i in a)), None)
        if pick is None:
            continue
        idx = list(pick)
        pos[:, j] = filled[:, idx].mean(axis=1)
        cf[:, j] = conf[:, idx].min(axis=1)
        have[j] = True
    if not (have[C.INDEX["Hips"]] and have[C.INDEX["Neck"]]):
        raise MotionError(
            "the person's torso (hips and neck or shoulders) is never detected",
            kind="unusable",
        )
    _derive(pos, have)
    return pos, cf, observed


def _to_joint_centres(pos: np.ndarray) -> None:
    """Move the detector's hips, neck and head points to where the canonical skeleton has
    those joints (``HIPS_ABOVE_HIP_JOINTS`` etc.), in place; the head keeps its direction
    from the neck, so nods and tilts stay."""
    hips, neck = pos[:, C.INDEX["Hips"]].copy(), pos[:, C.INDEX["Neck"]].copy()
    torso = neck - hips
    pos[:, C.INDEX["Hips"]] = hips + HIPS_ABOVE_HIP_JOINTS * torso
    pos[:, C.INDEX["Neck"]] = neck + NECK_ABOVE_SHOULDERS * torso
    head = pos[:, C.INDEX["Head"]] - neck
    norm = np.linalg.norm(head, axis=-1, keepdims=True)
    direction = np.where(norm > 1e-9, head / np.maximum(norm, 1e-12), torso)
    direction /= np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-12)
    length = HEAD_FROM_NECK * np.linalg.norm(torso, axis=-1, keepdims=True)
    pos[:, C.INDEX["Head"]] = pos[:, C.INDEX["Neck"]] + length * direction


def _derive(pos: np.ndarray, have: np.ndarray) -> None:
    """Place the joints not taken from the input, in place. ``pos (F, 22, 2)``.

    Always derived: Spine and Chest on the Hips->Neck segment at ``SPINE_FRACTION`` and
    ``CHEST_FRACTION``; Shoulder_L/R at ``SHOULDER_FRACTION`` of Neck->UpperArm;
    joint_Root later by ``place_root``. Never seen: a hip or shoulder mirrors the other
    one through Hips or Neck (or sits on it); a knee or elbow lies midway between its
    neighbours when the end point is seen, else hangs down the torso direction at the
    canonical proportions, as do a missing ankle, wrist or head; Toes sit on the ankle.
    Then Hips, Neck and Head move to the canonical joint centres (``_to_joint_centres``).
    """

    def p(name: str) -> np.ndarray:
        return pos[:, C.INDEX[name]]

    def put(name: str, value: np.ndarray) -> None:
        pos[:, C.INDEX[name]] = value
        have[C.INDEX[name]] = True

    hips, neck = p("Hips"), p("Neck")
    down = hips - neck  # (F, 2): one torso length, pointing from the neck to the hips
    if not have[C.INDEX["Head"]]:
        put("Head", neck - _HEAD_ABOVE_NECK * down)
    for side, other in (("L", "R"), ("R", "L")):
        for root, prox in ((hips, "UpperLeg"), (neck, "UpperArm")):
            if not have[C.INDEX[f"{prox}_{side}"]]:
                mirror = have[C.INDEX[f"{prox}_{other}"]]
                put(f"{prox}_{side}", 2 * root - p(f"{prox}_{other}") if mirror else root)
    for side in ("L", "R"):
        chains = (
            ("UpperLeg", "LowerLeg", "Foot", _THIGH, _SHIN),
            ("UpperArm", "LowerArm", "Hand", _UPPER_ARM, _FOREARM),
        )
        for prox, mid, end, first, second in chains:
            a, b, c = f"{prox}_{side}", f"{mid}_{side}", f"{end}_{side}"
            if not have[C.INDEX[b]]:
                if have[C.INDEX[c]]:
                    put(b, 0.5 * (p(a) + p(c)))
                else:
                    put(b, p(a) + first * down)
            if not have[C.INDEX[c]]:
                put(c, p(b) + second * down)
        if not have[C.INDEX[f"Toes_{side}"]]:
            put(f"Toes_{side}", p(f"Foot_{side}"))
    _to_joint_centres(pos)  # after mirroring through the detector's own mid-hip and neck
    put("Spine", hips + SPINE_FRACTION * (neck - hips))
    put("Chest", hips + CHEST_FRACTION * (neck - hips))
    for side in ("L", "R"):
        put(f"Shoulder_{side}", neck + SHOULDER_FRACTION * (p(f"UpperArm_{side}") - neck))


def place_root(pos: np.ndarray) -> None:
    """joint_Root (y up): under the Hips, at the lower ankle's height. In place."""
    root = C.INDEX["joint_Root"]
    pos[:, root, 0] = pos[:, C.INDEX["Hips"], 0]
    pos[:, root, 1] = np.minimum(pos[:, C.INDEX["Foot_L"], 1], pos[:, C.INDEX["Foot_R"], 1])

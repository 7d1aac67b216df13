"""The canonical skeleton every network reads and writes.

The 22-joint topology and names of the Bandai Namco data at 30 fps, re-expressed
with a T-pose rest: Y up, facing +Z, character's left on +X, identity joint
frames. Bone lengths are Bandai's (all its files share them). Directions of the
short bones (pelvis, spine, neck, clavicles, hips, feet) are the median of the
first frames of Bandai dataset-1 measured in the body frame
(``training/canonical_build.py`` recomputes them); arms lie along +-X and legs
along -Y, as a T-pose has them.
"""

from __future__ import annotations

import numpy as np

from motion import rotations as R
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton

FPS = 30.0

JOINTS: tuple[str, ...] = (
    "joint_Root", "Hips", "Spine", "Chest", "Neck", "Head",
    "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
    "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R",
    "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
    "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R",
)  # fmt: skip
PARENTS = np.array([-1, 0, 1, 2, 3, 4, 3, 6, 7, 8, 3, 10, 11, 12, 1, 14, 15, 16, 1, 18, 19, 20])
INDEX = {name: i for i, name in enumerate(JOINTS)}

# The joint whose direction from this one defines the bone this joint rotates.
MAIN_CHILD = {
    "joint_Root": "Hips", "Hips": "Spine", "Spine": "Chest", "Chest": "Neck", "Neck": "Head",
    "Shoulder_L": "UpperArm_L", "UpperArm_L": "LowerArm_L", "LowerArm_L": "Hand_L",
    "Shoulder_R": "UpperArm_R", "UpperArm_R": "LowerArm_R", "LowerArm_R": "Hand_R",
    "UpperLeg_L": "LowerLeg_L", "LowerLeg_L": "Foot_L", "Foot_L": "Toes_L",
    "UpperLeg_R": "LowerLeg_R", "LowerLeg_R": "Foot_R", "Foot_R": "Toes_R",
}  # fmt: skip


def _unit(v, length):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v) * length


def _mirror(v):
    return np.asarray(v) * np.array([-1.0, 1.0, 1.0])


_HIP_L = _unit([6.46, -2.19, 0.06], 6.83)
_SHOULDER_L = _unit([4.98, 12.84, 1.0], 13.92)
_TOES_L = _unit([0.0, -7.93, 7.96], 11.75)
_LEG_DROP = -(_HIP_L[1] - 39.08 - 40.99 + _TOES_L[1])  # T-pose toes touch y = 0

OFFSETS = np.array(
    [
        [0.0, 0.0, 0.0],  # joint_Root (on the floor)
        [0.0, _LEG_DROP, 0.0],  # Hips
        _unit([0.0, 15.74, -0.22], 15.74),  # Spine
        _unit([0.0, 8.99, 0.22], 8.99),  # Chest
        _unit([0.0, 16.18, 1.54], 16.38),  # Neck
        _unit([0.0, 6.34, 0.37], 6.46),  # Head
        _SHOULDER_L,
        [5.35, 0.0, 0.0],  # UpperArm_L (clavicle bone)
        [24.33, 0.0, 0.0],  # LowerArm_L (upper arm bone)
        [22.29, 0.0, 0.0],  # Hand_L (forearm bone)
        _mirror(_SHOULDER_L),
        [-5.35, 0.0, 0.0],
        [-24.33, 0.0, 0.0],
        [-22.29, 0.0, 0.0],
        _HIP_L,
        [0.0, -39.08, 0.0],  # LowerLeg_L (thigh bone)
        [0.0, -40.99, 0.0],  # Foot_L (shin bone)
        _TOES_L,
        _mirror(_HIP_L),
        [0.0, -39.08, 0.0],
        [0.0, -40.99, 0.0],
        _TOES_L,
    ]
)

_END_SITES = {
    INDEX["Head"]: ((0.0, 12.0, 1.0),),
    INDEX["Hand_L"]: ((8.0, 0.0, 0.0),),
    INDEX["Hand_R"]: ((-8.0, 0.0, 0.0),),
    INDEX["Toes_L"]: ((0.0, 0.0, 5.0),),
    INDEX["Toes_R"]: ((0.0, 0.0, 5.0),),
}

_CHANNELS = (
    ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
) * 2 + (("Zrotation", "Yrotation", "Xrotation"),) * 20

SKELETON = Skeleton(
    names=JOINTS, parents=PARENTS, offsets=OFFSETS, channels=_CHANNELS, end_sites=_END_SITES
)


def leg_length() -> float:
    """Hip-to-ankle length (thigh + shin), the scale for root trajectories."""
    return float(
        np.linalg.norm(OFFSETS[INDEX["LowerLeg_L"]]) + np.linalg.norm(OFFSETS[INDEX["Foot_L"]])
    )


def body_height() -> float:
    """Standing height of the canonical T-pose: floor to the top of the head (End Site)."""
    rest = SKELETON.rest_positions()
    top = rest[INDEX["Head"], 1] + _END_SITES[INDEX["Head"]][0][1]
    return float(top - rest[:, 1].min())


def template_directions() -> dict[str, np.ndarray]:
    """Unit direction of each joint's main bone in the canonical T-pose."""
    out = {}
    for joint, child in MAIN_CHILD.items():
        v = OFFSETS[INDEX[child]]
        out[joint] = v / np.linalg.norm(v)
    return out


# Bandai's rest pose lies flat along X (rotated joint frames), so retargeting uses
# this standing pose of its rig instead: the mean local rotations of the upright
# first frames of dataset-1, hips turned to face +Z (training/canonical_build.py).
BANDAI_REFERENCE_LROT = np.array(
    [
        [0.0, 0.0, 0.0, 1.0],
        [-0.01556, -0.00461, 0.70697, 0.70705],
        [-0.71036, 0.03099, -0.03092, -0.70248],
        [-0.01084, -0.002, -0.02633, -0.99959],
        [-0.00542, 0.00218, -0.02404, 0.99969],
        [-0.016, 0.0012, -0.00418, 0.99986],
        [-0.50054, -0.51276, -0.50099, 0.48533],
        [-0.02051, 0.00297, 0.53142, -0.84685],
        [0.02879, -0.35708, 0.02133, 0.93339],
        [-0.07449, 0.02222, -0.14563, -0.98628],
        [-0.53546, 0.50842, -0.4578, -0.49519],
        [-0.01302, -0.01383, 0.51753, -0.85545],
        [0.05233, -0.34135, 0.02698, 0.93809],
        [-0.07564, 0.03889, -0.16011, -0.98343],
        [-0.12973, 0.04481, -0.99005, 0.03101],
        [0.00057, -0.33755, -0.00018, -0.94131],
        [0.01715, 0.49141, -0.00523, -0.87075],
        [-0.00205, -0.16249, 0.00088, 0.98671],
        [-0.98941, -0.00342, 0.11907, -0.08297],
        [-0.00072, 0.30323, 0.00038, 0.95292],
        [0.05254, 0.49658, -0.03874, -0.86553],
        [-0.00181, -0.15849, 0.00123, 0.98736],
    ]
)


def check_motion(motion: Motion, what: str) -> None:
    """``MotionError`` (kind "unusable") unless ``motion`` is on the canonical skeleton (same
    joint names) at :data:`FPS`; ``what`` names the consumer in the message."""
    if motion.skeleton.names != JOINTS or abs(motion.fps - FPS) > 1e-3:
        raise MotionError(
            f"{what} need a canonical motion ({len(JOINTS)} joints) at {FPS:g} fps, got "
            f"{motion.skeleton.num_joints} joints at {motion.fps:g} fps",
            kind="unusable",
        )


# Each joint's counterpart on the other side (itself on the midline).
MIRROR_INDEX = np.array(
    [INDEX[n[:-1] + {"L": "R", "R": "L"}[n[-1]]] if n[-2:] in ("_L", "_R") else i
     for i, n in enumerate(JOINTS)]
)  # fmt: skip


def mirror_rotations(lrot: np.ndarray) -> np.ndarray:
    """Local rotations ``(F, 22, 4)`` (x, y, z, w) of the canonical skeleton reflected
    through its midline plane (x -> -x): each joint takes its counterpart's rotation,
    reflected. Reflecting a rotation keeps its x component and negates y and z (the axis
    is mirrored and, a reflection being improper, the sense flips)."""
    return np.asarray(lrot)[:, MIRROR_INDEX] * np.array([1.0, -1.0, -1.0, 1.0])


def mirrored(motion: Motion) -> Motion:
    """A canonical motion performed the other way round (left and right swapped): its
    global positions are the original's with x negated and sides exchanged. The canonical
    skeleton is symmetric, so the offsets stay; a translation's x is negated."""
    check_motion(motion, "mirroring")
    lpos = np.asarray(motion.lpos)[:, MIRROR_INDEX] * np.array([-1.0, 1.0, 1.0])
    return Motion(motion.skeleton, motion.fps, mirror_rotations(motion.lrot), lpos)


def turned(motion: Motion, rate: float, facing: float = 0.0) -> Motion:
    """A canonical motion turning ``rate`` rad/s more to its left (about +Y) as it goes,
    and its body facing ``facing`` rad further left of its path: the Hips' rotation is
    turned by both, its steps on the floor by the turn alone (its height unchanged)."""
    check_motion(motion, "turning")
    angle = rate * np.arange(motion.num_frames) / motion.fps
    lrot, lpos = np.array(motion.lrot, dtype=np.float64), np.array(motion.lpos)
    hips = INDEX["Hips"]
    lrot[:, hips] = R.mul(R.about_y(angle + facing), lrot[:, hips])
    steps = np.diff(lpos[:, hips], axis=0) * np.array([1.0, 0.0, 1.0])
    path = np.cumsum(R.apply(R.about_y(angle[1:]), steps), axis=0)
    lpos[1:, hips, [0, 2]] = lpos[0, hips, [0, 2]] + path[:, [0, 2]]
    return Motion(motion.skeleton, motion.fps, lrot, lpos)

"""Anatomy a result must keep: knees and elbows are hinges that bend one way, and no joint
moves faster than real mocap does.

Hinges, on the canonical skeleton (identity joint frames, T-pose rest): the knee
(``LowerLeg_*``) turns the shin in the thigh's frame, the elbow (``LowerArm_*``) the forearm
in the upper arm's. In all 454 Bandai takes the shin never points forward of the thigh
(its +Z component in the thigh's frame stays <= 0.005) and the forearm never behind the
upper arm (its +Z component >= -0.007): the knee flexes about the thigh's X axis, the
elbow about the upper arm's Y axis, one way only. :func:`hinged` turns a bend the wrong
way back to straight about that axis, keeping the bone's twist and its sideways part.

Speed: the fastest joint in any Bandai take (a sprint's toes) moves at 6.8 body heights a
second; :data:`SPEED_LIMIT` is what a time warp may push a result's fastest joint to
(:func:`capped_warp`).
"""

from __future__ import annotations

import numpy as np

from motion import canonical as C
from motion import kinematics as K
from motion import rotations as R
from motion.features import FACING_JOINTS
from motion.skeleton import Motion

# (hinge joint, its child, hinge axis in the parent's frame, forward-bend sign): the child
# bone's component along ``bend`` must be >= 0
HINGES = (
    ("LowerLeg_L", "Foot_L", np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])),
    ("LowerLeg_R", "Foot_R", np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])),
    ("LowerArm_L", "Hand_L", np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])),
    ("LowerArm_R", "Hand_R", np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])),
)
KNEES = ("LowerLeg_L", "LowerLeg_R")
ELBOWS = ("LowerArm_L", "LowerArm_R")
# A knee is "backwards" when it lies this share of body height behind the hip-ankle line
# with the leg bent by at least BENT_DEGREES (the yardstick; in Bandai's 454 takes:
# 3 frames of 76,197, all in one dance take)
BACKWARDS_SHARE = 0.02
BENT_DEGREES = 15.0
SPEED_LIMIT = 7.0  # body heights per second a time warp may push the fastest joint to


def _bend_angle(d: np.ndarray, rest: np.ndarray, axis: np.ndarray, bend: np.ndarray) -> np.ndarray:
    """The angle ``(F,)`` about ``axis`` from the rest direction to the bone direction ``d``
    projected on the hinge plane, positive toward ``bend``."""
    return np.arctan2(d @ bend, d @ rest)


def hinged(motion: Motion, joints: tuple[str, ...] = KNEES + ELBOWS) -> Motion:
    """A canonical motion with each hinge of ``joints`` bent no further than straight the
    wrong way: where the child bone points against the hinge's bend direction, the joint's
    local rotation is turned about the hinge axis until it is straight in that plane
    (its twist and sideways component kept). Already-valid frames are left bit for bit."""
    C.check_motion(motion, "the hinge constraint")
    lrot = motion.lrot.copy()
    for joint, child, axis, bend in HINGES:
        if joint not in joints:
            continue
        j = C.INDEX[joint]
        rest = C.OFFSETS[C.INDEX[child]] / np.linalg.norm(C.OFFSETS[C.INDEX[child]])
        d = R.apply(lrot[:, j], rest)
        angle = _bend_angle(d, rest, axis, bend)
        wrong = angle < 0.0
        if not wrong.any():
            continue
        # rotating about ``axis`` by t turns rest toward ``bend`` when cross(axis, rest)
        # points along bend; else the other way
        sense = np.sign(np.dot(np.cross(axis, rest), bend))
        turn = R.from_rotvec(axis[None] * (sense * -angle[wrong])[:, None])
        lrot[wrong, j] = R.mul(turn, lrot[wrong, j])
    return motion.replace(lrot=lrot)


def knees_backwards(motion: Motion) -> np.ndarray:
    """Per frame ``(F,)``, whether either knee of a canonical motion lies more than
    :data:`BACKWARDS_SHARE` of body height behind its hip-ankle line (behind: against the
    body's facing on the floor) with the leg bent by :data:`BENT_DEGREES` or more."""
    C.check_motion(motion, "the knee measure")
    gpos = K.global_positions(motion)
    forward = K.facing_directions(gpos, *FACING_JOINTS)
    out = np.zeros(motion.num_frames, dtype=bool)
    for side in "LR":
        hip, knee, ankle = (
            gpos[:, C.INDEX[f"{n}_{side}"]] for n in ("UpperLeg", "LowerLeg", "Foot")
        )
        line = ankle - hip
        t = np.einsum("fi,fi->f", knee - hip, line) / np.maximum(
            np.einsum("fi,fi->f", line, line), 1e-9
        )
        off = knee - (hip + t[:, None] * line)
        thigh, shin = knee - hip, ankle - knee
        cos = np.einsum("fi,fi->f", thigh, shin) / np.maximum(
            np.linalg.norm(thigh, axis=-1) * np.linalg.norm(shin, axis=-1), 1e-9
        )
        bent = cos <= np.cos(np.radians(BENT_DEGREES))
        out |= bent & (np.einsum("fi,fi->f", off, forward) < -BACKWARDS_SHARE * C.body_height())
    return out


def joint_speeds(motion: Motion) -> np.ndarray:
    """Each joint's speed ``(F - 1, J)`` of a canonical motion, in body heights (floor to
    the top of the head, :func:`motion.canonical.body_height`) per second."""
    C.check_motion(motion, "joint speeds")
    gpos = K.global_positions(motion)
    step = np.linalg.norm(np.diff(gpos, axis=0), axis=-1)
    return step * motion.fps / C.body_height()


def peak_speed(motion: Motion) -> float:
    """The fastest any joint of ``motion`` moves, in body heights per second (0 for one
    frame)."""
    if motion.num_frames < 2:
        return 0.0
    return float(joint_speeds(motion).max())


def capped_warp(factor: float, motion: Motion, limit: float = SPEED_LIMIT) -> float:
    """A time-warp ``factor`` (> 1 plays faster) lowered so the warped ``motion``'s fastest
    joint moves at most ``limit`` body heights a second; never below 1 on that account
    (a warp does not slow down a result that is already fast)."""
    if factor <= 1.0:
        return factor
    peak = peak_speed(motion)
    if peak * factor <= limit:
        return factor
    return max(1.0, limit / peak) if peak > 0 else factor

"""Anatomy a result must keep: knees and elbows are hinges that bend one way, and no joint
moves faster than real mocap does.

Hinges, on the canonical skeleton (identity joint frames, T-pose rest): the knee
(``LowerLeg_*``) turns the shin in the thigh's frame, the elbow (``LowerArm_*``) the forearm
in the upper arm's. In all 454 Bandai takes the shin never points forward of the thigh
(its +Z component in the thigh's frame stays <= 0.005) and the forearm never behind the
upper arm (its +Z component >= -0.007): the knee flexes about the thigh's X axis, the
elbow about the upper arm's Y axis, one way only. :func:`hinged` turns a bend the wrong
way back to straight about that axis, keeping the bone's twist and its sideways part.

A leg IK can also swing a knee behind its leg with the hinge itself intact (the leg turned
about its hip-ankle line): :func:`knees_forward` turns it back, the foot held.

Measures: :func:`knees_backwards` (the knee behind the hip-ankle line, against the body's
facing) and :func:`elbows_backwards` (the elbow off the shoulder-wrist line on the side
its forearm flexes toward, in the upper arm's own frame); neither finds a frame in
Bandai's 454 takes but 3 knee frames of one dance take.

Speed: the fastest joint in any Bandai take (a sprint's toes) moves at 6.8 body heights a
second; :data:`SPEED_LIMIT` is what a result may not exceed where its content does not
(:func:`despiked`), and what a time warp slows a result to where a joint would go faster
(:func:`speed_limited_warp`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d, label, maximum_filter1d, minimum_filter1d

from motion import canonical as C
from motion import kinematics as K
from motion import rotations as R
from motion.errors import MotionError
from motion.features import FACING_JOINTS, time_warp
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
SPEED_LIMIT = 7.0  # body heights a second: a result's fastest joint (real Bandai's: 6.85)
SWIVEL_BLEND_SECONDS = 0.2  # how far either side of a swivelled knee the swivel fades
SWIVEL_TOLERANCE = BACKWARDS_SHARE / 2  # how far behind its line a knee may stay
SPIKE_REACH = 4  # frames a side :func:`despiked` may bridge over (0.13 s at 30 fps)


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


def _off_line(gpos: np.ndarray, top: str, middle: str, end: str) -> tuple[np.ndarray, np.ndarray]:
    """Where the ``middle`` joint of a limb lies off its ``top``-``end`` line ``(F, 3)``,
    and whether the limb is bent by :data:`BENT_DEGREES` or more ``(F,)``."""
    a, b, c = (gpos[:, C.INDEX[n]] for n in (top, middle, end))
    line = c - a
    t = np.einsum("fi,fi->f", b - a, line) / np.maximum(np.einsum("fi,fi->f", line, line), 1e-9)
    off = b - (a + t[:, None] * line)
    upper, lower = b - a, c - b
    cos = np.einsum("fi,fi->f", upper, lower) / np.maximum(
        np.linalg.norm(upper, axis=-1) * np.linalg.norm(lower, axis=-1), 1e-9
    )
    return off, cos <= np.cos(np.radians(BENT_DEGREES))


def knees_backwards(motion: Motion) -> np.ndarray:
    """Per frame ``(F,)``, whether either knee of a canonical motion lies more than
    :data:`BACKWARDS_SHARE` of body height behind its hip-ankle line (behind: against the
    body's facing on the floor) with the leg bent by :data:`BENT_DEGREES` or more."""
    C.check_motion(motion, "the knee measure")
    gpos = K.global_positions(motion)
    forward = K.facing_directions(gpos, *FACING_JOINTS)
    out = np.zeros(motion.num_frames, dtype=bool)
    for side in "LR":
        off, bent = _off_line(gpos, f"UpperLeg_{side}", f"LowerLeg_{side}", f"Foot_{side}")
        out |= bent & (np.einsum("fi,fi->f", off, forward) < -BACKWARDS_SHARE * C.body_height())
    return out


def knees_forward(motion: Motion, blend_seconds: float = SWIVEL_BLEND_SECONDS) -> Motion:
    """A canonical motion with every bent knee swivelled out of the way :func:`knees_backwards`
    measures: where a knee lies further than :data:`SWIVEL_TOLERANCE` of body height behind
    its hip-ankle line (against the body's facing), the whole leg turns about that line by
    the least angle that brings it within, the swivel an animator uses. The ankle's position
    and the foot's global rotation stay (contacts hold), and so does the knee's bend; the
    angle is spread over ``blend_seconds`` either side, so the leg does not pop. Frames that
    need nothing near them stay bit for bit."""
    C.check_motion(motion, "the knee swivel")
    parents = motion.skeleton.parents
    legs = [C.INDEX[f"{n}_{s}"] for s in "LR" for n in ("UpperLeg", "LowerLeg", "Foot")]
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=legs + list(FACING_JOINTS))
    forward = K.facing_directions(gpos, *FACING_JOINTS)
    reach = max(1, int(round(blend_seconds * motion.fps)))
    lrot = motion.lrot.copy()
    for side in "LR":
        hip, knee, foot = (C.INDEX[f"{n}_{side}"] for n in ("UpperLeg", "LowerLeg", "Foot"))
        off, bent = _off_line(gpos, f"UpperLeg_{side}", f"LowerLeg_{side}", f"Foot_{side}")
        line = gpos[:, foot] - gpos[:, hip]
        axis = line / np.maximum(np.linalg.norm(line, axis=-1, keepdims=True), 1e-9)
        ahead = forward - np.einsum("fi,fi->f", forward, axis)[:, None] * axis
        across = np.cross(axis, ahead)
        phi = np.arctan2(np.einsum("fi,fi->f", off, across), np.einsum("fi,fi->f", off, ahead))
        # behind by at most SWIVEL_TOLERANCE: cos(phi) >= -tolerance / (|off| |ahead|)
        scale = np.linalg.norm(off, axis=-1) * np.linalg.norm(ahead, axis=-1)
        least = -np.minimum(SWIVEL_TOLERANCE * C.body_height() / np.maximum(scale, 1e-9), 1.0)
        wrong = bent & (np.cos(phi) < least)
        if not wrong.any():
            continue
        # Knees behind on either side of straight back turn out to one side per stretch
        # (the side most of its frames are on), so the swivel never flips the knee across.
        runs, count = label(maximum_filter1d(wrong, 4 * reach + 1))
        toward = np.ones(len(phi))
        for run in range(1, count + 1):
            here = runs == run
            toward[here] = 1.0 if np.sin(phi[here & wrong]).sum() >= 0.0 else -1.0
        on_side = np.where(np.sign(phi) == toward, phi, phi + toward * 2 * np.pi)
        need = np.where(wrong, toward * np.arccos(least) - on_side, 0.0)  # of sign -toward
        spread = gaussian_filter1d(maximum_filter1d(np.abs(need), 2 * reach + 1), reach / 2)
        turn = -toward * np.maximum(spread, np.abs(need))
        moved = np.abs(turn) > 1e-6
        q = R.from_rotvec(axis[moved] * turn[moved, None])
        thigh = R.mul(q, grot[moved, hip])
        lrot[moved, hip] = R.mul(R.inv(grot[moved, int(parents[hip])]), thigh)
        shin = R.mul(q, grot[moved, knee])
        lrot[moved, foot] = R.mul(R.inv(shin), grot[moved, foot])
    return motion.replace(lrot=lrot)


def elbows_backwards(motion: Motion) -> np.ndarray:
    """Per frame ``(F,)``, whether either elbow of a canonical motion is bent the way it
    cannot bend: the arm bent by :data:`BENT_DEGREES` or more with the elbow more than
    :data:`BACKWARDS_SHARE` of body height off its shoulder-wrist line on the side the
    forearm flexes toward (the upper arm's bend direction, :data:`HINGES`), where a flexed
    elbow lies on the other side. The shoulder turns freely, so the upper arm's own frame
    says which side is which, not the body's facing as for knees."""
    C.check_motion(motion, "the elbow measure")
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    out = np.zeros(motion.num_frames, dtype=bool)
    for joint, child, _, bend in HINGES:
        if joint not in ELBOWS:
            continue
        side = joint[-1]
        flexes_toward = R.apply(grot[:, C.INDEX[f"UpperArm_{side}"]], bend)
        off, bent = _off_line(gpos, f"UpperArm_{side}", joint, child)
        out |= bent & (
            np.einsum("fi,fi->f", off, flexes_toward) > BACKWARDS_SHARE * C.body_height()
        )
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


def _bridged(motion: Motion, a: int, b: int) -> Motion:
    """``motion`` with frames strictly between ``a`` and ``b`` replaced by an even passage
    from frame ``a``'s pose to frame ``b``'s (slerp for rotations, linear for translations)."""
    w = (np.arange(a + 1, b) - a) / (b - a)
    lrot, lpos = motion.lrot.copy(), motion.lpos.copy()
    lrot[a + 1 : b] = R.slerp(lrot[a][None], lrot[b][None], w[:, None])
    lpos[a + 1 : b] = lpos[a] + w[:, None, None] * (lpos[b] - lpos[a])
    return motion.replace(lrot=lrot, lpos=lpos)


def despiked(
    motion: Motion, content: Motion, limit: float = SPEED_LIMIT, reach: int = SPIKE_REACH
) -> Motion:
    """A canonical result without the jumps no body makes: where a joint moves faster than
    ``limit`` body heights a second and faster than the same joint of ``content`` (the
    clip it restyles, frame for frame) at that step, the frames around the step become an
    even passage between the poses on either side (:func:`_bridged`), widened one frame a
    side at a time, up to ``reach`` frames a side, until no joint in it exceeds what is
    allowed there (else the passage that exceeds it least). Steps within the allowance
    are left bit for bit. Such steps are not motion: a network's upper arm turning 130
    degrees about its own axis in one frame (the bent forearm swings the hand round), a
    foot clean-up turning a foot flat at once."""
    C.check_motion(motion, "the speed clean-up")
    if motion.num_frames != content.num_frames:
        raise MotionError("the speed clean-up: the result and its content differ in length")
    if motion.num_frames < 3:
        return motion
    speeds = joint_speeds(motion)
    if not (speeds > limit).any():
        return motion
    allowed = np.maximum(joint_speeds(content), limit)
    last = motion.num_frames - 1
    for f in np.flatnonzero((speeds > allowed).any(axis=1)):
        if not (speeds[f] > allowed[f]).any():
            continue  # an earlier passage covered it
        best, least = motion, np.inf
        for k in range(1, reach + 1):
            a, b = max(f - k, 0), min(f + 1 + k, last)
            trial = _bridged(motion, a, b)
            excess = float((joint_speeds(trial.slice(a, b + 1)) - allowed[a:b]).max())
            if excess < least:
                best, least = trial, excess
            if excess <= 0.0:
                break
        motion = best
        speeds = joint_speeds(motion)
    return motion


@dataclass(frozen=True)
class Warp:
    """A time warp: a clip played ``factor`` times as fast overall (> 1 shortens it), at an
    even rate when ``source`` and ``played`` are None, else along the map they give: at
    share ``played[i]`` of the warped clip's duration it is at share ``source[i]`` of the
    clip's (both running from 0 to 1, piecewise linear between), so that a clip at any
    frame rate, the canonical result or the request's own, is warped alike and keeps its
    first and last frames (a cycle still loops)."""

    factor: float = 1.0
    source: np.ndarray | None = None
    played: np.ndarray | None = None

    @property
    def identity(self) -> bool:
        return self.factor == 1.0 and self.source is None

    def apply(self, motion: Motion) -> Motion:
        """``motion`` played along this warp, at its own frame rate."""
        if self.source is None:
            return time_warp(motion, self.factor) if self.factor != 1.0 else motion
        frames = max(int(round((motion.num_frames - 1) / self.factor)) + 1, 2)
        share = np.interp(np.linspace(0.0, 1.0, frames), self.played, self.source)
        return K.resample_at(motion, share * (motion.num_frames - 1), motion.fps)


def speed_limited_warp(factor: float, motion: Motion, limit: float = SPEED_LIMIT) -> Warp:
    """A time warp of the canonical ``motion`` by ``factor``, slowed where a joint would
    move faster than ``limit`` body heights a second: each step plays at ``factor``, or at
    ``limit`` over its fastest joint's speed where that is less (below 1 too: the warp
    slows down a result faster than real mocap), the rate eased in and out over about two
    frames either side (a minimum over 5 frames, then a Gaussian of 1 frame, never above
    the step's own limit). Without such a step, the even warp by ``factor``."""
    if motion.num_frames < 3:
        return Warp(factor)
    fastest = joint_speeds(motion).max(axis=1)
    own = np.where(fastest * factor > limit, limit / np.maximum(fastest, 1e-9), factor)
    if (own >= factor).all():
        return Warp(factor)
    rate = gaussian_filter1d(minimum_filter1d(own, 5, mode="nearest"), 1.0, mode="nearest")
    rate = np.minimum(rate, own)
    played = np.concatenate([[0.0], np.cumsum(1.0 / rate)])
    overall = (motion.num_frames - 1) / played[-1]
    source = np.linspace(0.0, 1.0, motion.num_frames)
    return Warp(float(overall), source, played / played[-1])

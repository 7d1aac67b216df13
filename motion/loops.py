"""Cycles: telling that a clip loops, and keeping a result of it looping.

A clip loops when its last pose matches its first with the travel of the root aside
(:func:`detect`): either it repeats the first frame at the end (a *closed* cycle, as
Mixamo and most game exports write it) or its last frame leads into the first one step on
(an *open* one). Poses are compared as root-local joint positions (on the canonical
skeleton at 30 fps: the hips' place on the floor and their heading taken out) in units of
the clip's median frame-to-frame step, so the tolerance does not depend on speed or size.

The tolerances come from real cycles, measured so: an exported closed loop meets within
rounding (0 steps); the walks of ``cmu-31`` (02_01, 07_01, 08_01, 08_11), cut every 5
frames at the best-matching frame one gait cycle on, meet within 1.0-2.6 steps (median
1.5-1.9: a performer never repeats a stride exactly); the first and last frames of the 24
foreign takes ``make eval-foreign`` reads (T-pose frames left out) lie 2.3-35 steps apart.
So a gap up to :data:`CLOSED_GAP` of a step is a closed cycle, up to :data:`OPEN_GAP` an
open one: authored loops and most hand-cut mocap cycles are found, no foreign take is;
``loop=true`` takes a clip as a loop whatever its gap.

A result keeps looping when every step that looks at neighbouring frames (the networks'
windows, the smoothing, the foot clean-up) sees the cycle wrap around: :class:`Cycle`
extends a closed canonical cycle by ``margin`` frames of itself on both sides (the root
carried on by the cycle's own travel and turn), and crops the processed result back,
spreading what still differs between its ends over the cycle so that the last frame is
the first moved on by one cycle's travel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion import canonical as C
from motion import kinematics as K
from motion import rotations as R
from motion.skeleton import Motion

CLOSED_GAP = 0.5  # median steps: the last frame repeats the first
OPEN_GAP = 2.0  # median steps: the last frame leads into the first
HIPS = C.INDEX["Hips"]


def local_poses(motion: Motion) -> np.ndarray:
    """Positions ``(F, 21, 3)`` of a canonical motion's joints from the hips down (not
    joint_Root, which stays at the origin) relative to the hips' place on the floor,
    turned so the hips' heading is +Z."""
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    heading = R.yaw(grot[:, HIPS])
    return K.root_local(gpos[:, HIPS:], gpos[:, HIPS], heading)


def gap_in_steps(motion: Motion) -> float:
    """How far the last pose is from the first, in median frame-to-frame steps (mean joint
    distance of :func:`local_poses`); ``inf`` for a clip under 3 frames or one that does
    not move."""
    if motion.num_frames < 3:
        return float("inf")
    local = local_poses(motion)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    step = float(np.median(steps))
    if step <= 1e-9 * max(C.body_height(), 1.0):
        return float("inf")
    return float(np.linalg.norm(local[-1] - local[0], axis=-1).mean()) / step


@dataclass(frozen=True)
class Loop:
    """A looping clip: ``closed`` when its last frame repeats its first, else open (the
    first frame follows the last), and the gap between them in median steps."""

    closed: bool
    gap: float


def detect(motion: Motion, force: bool = False) -> Loop | None:
    """Whether the canonical ``motion`` loops (module docstring): closed when its ends are
    within :data:`CLOSED_GAP` of a step at its own rate, open within :data:`OPEN_GAP` of a
    step at 30 fps (a step at 120 fps is a quarter of one); with ``force`` (the client says
    it loops) it is taken as one in any case."""
    gap = gap_in_steps(motion)
    if gap <= CLOSED_GAP:
        return Loop(True, gap)
    if gap * C.FPS / motion.fps <= OPEN_GAP or (force and motion.num_frames >= 3):
        return Loop(False, gap)
    return None


def _travel(motion: Motion, last: int) -> tuple[float, np.ndarray]:
    """The turn (radians about +Y) and shift on the floor ``(2,)`` that take the hips of
    frame 0 onto those of frame ``last``: ``p_last = R(turn) p_0 + shift``."""
    hips_rot = K.global_rotations(motion)[[0, last], HIPS]
    fwd = R.apply(hips_rot, np.array([0.0, 0.0, 1.0]))
    angle = np.arctan2(fwd[:, 0], fwd[:, 2])
    turn = float(np.angle(np.exp(1j * (angle[1] - angle[0]))))
    p = K.global_positions(motion)[[0, last], HIPS]
    turned = R.apply(R.about_y(turn), p[0] * [1.0, 0.0, 1.0])
    return turn, (p[1] - turned)[[0, 2]]


def _moved(motion: Motion, turn: float, shift: np.ndarray) -> Motion:
    """``motion`` turned about +Y by ``turn`` then shifted on the floor by ``shift`` (the
    canonical hips carry the path; joint_Root stays at the origin)."""
    lrot, lpos = motion.lrot.copy(), motion.lpos.copy()
    q = R.about_y(turn)
    lrot[:, HIPS] = R.mul(q, lrot[:, HIPS])
    lpos[:, HIPS] = R.apply(q, lpos[:, HIPS])
    lpos[:, HIPS, 0] += shift[0]
    lpos[:, HIPS, 2] += shift[1]
    return motion.replace(lrot=lrot, lpos=lpos)


def closed(motion: Motion, loop: Loop) -> Motion:
    """A canonical looping ``motion`` as a closed cycle: an open one gains a last frame,
    its first moved on by the travel and turn of its last step. Where the last frame does
    not lead into that one (a clip taken as a loop whatever its gap), what it misses is
    spread over the clip, nothing at the first frame and all of it at the new last one, so
    the cycle runs on without a jump."""
    if loop.closed:
        return motion
    frames = motion.num_frames
    turn, _ = _travel(motion, frames - 1)
    step_turn, _ = _travel(motion.slice(frames - 2), 1)
    turn_total = turn + step_turn
    hips = K.global_positions(motion)[:, HIPS]
    end = hips[-1] + (hips[-1] - hips[-2])
    start = R.apply(R.about_y(turn_total), hips[0] * [1.0, 0.0, 1.0])
    closing = _moved(motion.slice(0, 1), turn_total, (end - start)[[0, 2]])
    # the frame after the last as its last step would make it, against the closing frame
    step = R.mul(motion.lrot[-1], R.inv(motion.lrot[-2]))
    after_rot = R.mul(step, motion.lrot[-1])
    after_pos = 2 * motion.lpos[-1] - motion.lpos[-2]
    residual = R.mul(after_rot, R.inv(closing.lrot[0]))  # after = residual * closing
    weight = np.arange(frames) / frames
    undo = R.slerp(
        np.broadcast_to(R.IDENTITY, (frames, *residual.shape)),
        np.broadcast_to(R.inv(residual), (frames, *residual.shape)),
        weight[:, None],
    )
    lrot = R.mul(undo, motion.lrot)
    lpos = motion.lpos - weight[:, None, None] * (after_pos - closing.lpos[0])[None]
    return motion.replace(
        lrot=R.make_continuous(np.concatenate([lrot, closing.lrot])),
        lpos=np.concatenate([lpos, closing.lpos]),
    )


def with_closing_frame(motion: Motion, up: np.ndarray | None = None) -> Motion:
    """An open cycle on any rig with its first frame again after its last, the root
    joints' place on the floor carried one step on (in the upright world: ``up`` turns the
    file's world so +Y is up), their height the first frame's: what :func:`closed` adds on
    the canonical skeleton, for the joints a rig has beyond it."""
    up = R.IDENTITY if up is None else np.asarray(up, dtype=np.float64)
    roots = np.nonzero(motion.skeleton.parents < 0)[0]
    upright = R.apply(up, motion.lpos[:, roots])
    if motion.num_frames > 1:
        after = upright[-1] + (upright[-1] - upright[-2])
    else:
        after = upright[-1].copy()
    after[:, 1] = upright[0, :, 1]
    lpos = motion.lpos[:1].copy()
    lpos[0, roots] = R.apply(R.inv(up), after)
    return motion.replace(
        lrot=np.concatenate([motion.lrot, motion.lrot[:1]]),
        lpos=np.concatenate([motion.lpos, lpos]),
    )


@dataclass(frozen=True)
class Cycle:
    """A closed canonical cycle of ``frames`` steps (``frames + 1`` frames, the last the
    first moved on by ``turn`` and ``shift``), extended by ``margin`` frames each side."""

    frames: int
    turn: float
    shift: np.ndarray
    margin: int

    @staticmethod
    def of(motion: Motion, margin: int) -> Cycle:
        """The cycle of a closed canonical clip (:func:`closed`)."""
        turn, shift = _travel(motion, motion.num_frames - 1)
        return Cycle(motion.num_frames - 1, turn, shift, int(margin))

    def _power(self, k: int) -> tuple[float, np.ndarray]:
        """The turn and shift of ``k`` cycles (negative: back)."""
        turn, shift = 0.0, np.zeros(2)
        q = lambda a: R.about_y(a)  # noqa: E731
        one = np.array([self.shift[0], 0.0, self.shift[1]])
        for _ in range(abs(k)):
            if k > 0:  # T(T^k): R(R^k p + s_k) + s
                s3 = R.apply(q(self.turn), np.array([shift[0], 0.0, shift[1]])) + one
            else:  # T^-1: R^-1 (p - s)
                s3 = R.apply(q(-self.turn), np.array([shift[0], 0.0, shift[1]]) - one)
            turn += self.turn if k > 0 else -self.turn
            shift = s3[[0, 2]]
        return turn, shift

    def extended(self, motion: Motion) -> Motion:
        """The closed cycle ``motion`` with ``margin`` frames of the cycle before and after
        it, each carried on by as many cycles' travel as it lies away."""
        n = self.frames
        index = np.arange(-self.margin, n + 1 + self.margin)
        source, cycles = index % n, index // n
        lrot, lpos = motion.lrot[source].copy(), motion.lpos[source].copy()
        for k in np.unique(cycles):
            if k == 0:
                continue
            rows = cycles == k
            part = motion.replace(lrot=lrot[rows], lpos=lpos[rows])
            moved = _moved(part, *self._power(int(k)))
            lrot[rows], lpos[rows] = moved.lrot, moved.lpos
        return motion.replace(lrot=lrot, lpos=lpos)

    def cropped(self, motion: Motion) -> Motion:
        """A result of :meth:`extended`'s frames cut back to the cycle, what differs
        between its last frame and its first moved on by one cycle spread over the cycle
        (nothing at the first frame, all of it at the last)."""
        n = self.frames
        out = motion.slice(self.margin, self.margin + n + 1)
        target = _moved(out.slice(0, 1), self.turn, self.shift)
        weight = np.arange(n + 1) / n
        residual = R.mul(out.lrot[-1], R.inv(target.lrot[0]))  # (J, 4): last = r * target
        undo = R.slerp(
            np.broadcast_to(R.IDENTITY, (n + 1, *residual.shape)),
            np.broadcast_to(R.inv(residual), (n + 1, *residual.shape)),
            weight[:, None],
        )
        lrot = R.make_continuous(R.mul(undo, out.lrot))
        lpos = out.lpos - weight[:, None, None] * (out.lpos[-1] - target.lpos[0])[None]
        return out.replace(lrot=lrot, lpos=lpos)


def loop_jump(motion: Motion) -> tuple[float, float]:
    """The jump at the loop point of a canonical motion (its last pose against its first,
    mean joint distance of :func:`local_poses`) and its median frame-to-frame step."""
    local = local_poses(motion)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    jump = float(np.linalg.norm(local[-1] - local[0], axis=-1).mean())
    return jump, float(np.median(steps))

"""Forward kinematics and the derived quantities networks and clean-up passes use.

All functions leave their inputs alone and broadcast over leading dimensions;
forward kinematics is compiled (``motion.kernels``).
"""

from __future__ import annotations

import numpy as np

from motion import kernels
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion

UP = np.array([0.0, 1.0, 0.0])
FORWARD = np.array([0.0, 0.0, 1.0])


def levels(parents: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The joints below the root grouped by depth, top first: ``(joints, their parents)``
    per level. Every joint of a level can be posed at once once the level above is."""
    parents = np.asarray(parents)
    depth = np.zeros(len(parents), dtype=int)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    out = []
    for d in range(1, int(depth.max(initial=0)) + 1):
        joints = np.nonzero(depth == d)[0]
        out.append((joints, parents[joints]))
    return out


def fk(
    lrot: np.ndarray, lpos: np.ndarray, parents: np.ndarray, joints: list[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations ``(..., J, 4)`` and positions ``(..., J, 3)`` from local ones.

    ``lrot (..., J, 4)``, ``lpos (..., J, 3)``: a joint's rotation and its translation
    from its parent (the root's is its world position); ``parents (J,)`` parents first.
    Loops over joints, never frames. With ``joints``, only those and their ancestors are
    posed, the others left zero (the foot clean-up needs the legs, not the arms and head).
    """
    lrot = np.asarray(lrot, dtype=np.float64)
    lpos = np.asarray(lpos, dtype=np.float64)
    shape = np.broadcast_shapes(lrot.shape[:-1], lpos.shape[:-1])
    joint_count = shape[-1]
    lrot = np.ascontiguousarray(np.broadcast_to(lrot, shape + (4,))).reshape(-1, joint_count, 4)
    lpos = np.ascontiguousarray(np.broadcast_to(lpos, shape + (3,))).reshape(-1, joint_count, 3)
    posed = with_ancestors(parents, range(joint_count) if joints is None else joints)
    grot, gpos = kernels.fk(lrot, lpos, np.asarray(parents, dtype=np.int64), posed)
    return grot.reshape(shape + (4,)), gpos.reshape(shape + (3,))


def repose(
    grot: np.ndarray,
    gpos: np.ndarray,
    lrot: np.ndarray,
    lpos: np.ndarray,
    parents: np.ndarray,
    joints: list[int],
) -> None:
    """:func:`fk`'s ``grot``/``gpos (..., J, 4|3)`` brought up to date in place after the
    local rotations of ``joints`` (parents first, with every posed joint below them)
    changed: those joints posed again, by the same arithmetic."""
    for j in joints:
        p = parents[j]
        gpos[..., j, :] = rot.apply(grot[..., p, :], lpos[..., j, :]) + gpos[..., p, :]
        grot[..., j, :] = rot.mul(grot[..., p, :], lrot[..., j, :])


def with_ancestors(parents: np.ndarray, joints) -> np.ndarray:
    """``(J,)`` bool: ``joints`` and every joint above them."""
    out = np.zeros(len(parents), dtype=bool)
    for j in joints:
        while j >= 0 and not out[j]:
            out[j] = True
            j = int(parents[j])
    return out


def global_positions(motion: Motion) -> np.ndarray:
    """World joint positions ``(F, J, 3)`` of a motion."""
    return fk(motion.lrot, motion.lpos, motion.skeleton.parents)[1]


def global_rotations(motion: Motion) -> np.ndarray:
    """World joint rotations ``(F, J, 4)`` of a motion."""
    return fk(motion.lrot, motion.lpos, motion.skeleton.parents)[0]


def local_from_global(grot: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Local rotations ``(..., J, 4)`` from global ones (inverse of the rotation part of fk)."""
    grot = np.asarray(grot, dtype=np.float64)
    lrot = grot.copy()
    par = np.asarray(parents)
    lrot[..., 1:, :] = rot.mul(rot.inv(grot[..., par[1:], :]), grot[..., 1:, :])
    return lrot


def facing_directions(
    gpos: np.ndarray,
    left_hip: int,
    right_hip: int,
    left_shoulder: int,
    right_shoulder: int,
    smooth: int = 0,
) -> np.ndarray:
    """Unit facing directions on the floor ``(F, 3)`` from hip and shoulder positions ``(F, J, 3)``.

    The body's left-to-right axis crossed with up gives forward; ``smooth`` > 0
    applies a Gaussian of that many frames (sigma) so turns are not jittery.
    """
    across = (gpos[..., left_hip, :] - gpos[..., right_hip, :]) + (
        gpos[..., left_shoulder, :] - gpos[..., right_shoulder, :]
    )
    fwd = np.cross(across, UP)
    fwd[..., 1] = 0.0
    if smooth > 0 and fwd.ndim == 2 and len(fwd) > 1:
        from scipy.ndimage import gaussian_filter1d

        fwd = gaussian_filter1d(fwd, smooth, axis=0, mode="nearest")
    norm = np.linalg.norm(fwd, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, fwd / np.maximum(norm, 1e-9), FORWARD)


def facing_rotations(directions: np.ndarray) -> np.ndarray:
    """Rotations about +Y ``(F, 4)`` that turn +Z onto each facing direction ``(F, 3)``."""
    return rot.about_y(np.arctan2(directions[..., 0], directions[..., 2]))


def root_local(gpos: np.ndarray, root_xz: np.ndarray, facing: np.ndarray) -> np.ndarray:
    """Positions ``(F, J, 3)`` relative to the root on the floor, in the facing frame.

    ``root_xz (F, 3)`` is the reference point (its height is ignored), ``facing (F, 4)``
    rotations about +Y; the result faces +Z in every frame.
    """
    ref = np.array(root_xz, dtype=np.float64, copy=True)
    ref[..., 1] = 0.0
    rel = gpos - ref[..., None, :]
    return rot.apply(rot.inv(facing)[..., None, :], rel)


def root_velocities(
    root_xz: np.ndarray, facing: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Root velocity on the floor in the facing frame ``(F, 2)`` (sideways x, forward z)
    and turning velocity ``(F,)`` in radians per second; the last frame repeats the one before.
    """
    delta = np.zeros_like(root_xz, dtype=np.float64)
    delta[:-1] = root_xz[1:] - root_xz[:-1]
    if len(delta) > 1:
        delta[-1] = delta[-2]
    delta[..., 1] = 0.0
    local = rot.apply(rot.inv(facing), delta) * fps
    fwd = rot.apply(facing, FORWARD)
    ang = np.unwrap(np.arctan2(fwd[..., 0], fwd[..., 2]))
    turn = np.zeros_like(ang)
    turn[:-1] = (ang[1:] - ang[:-1]) * fps
    if len(turn) > 1:
        turn[-1] = turn[-2]
    return local[..., [0, 2]], turn


def integrate_root(
    velocity: np.ndarray,
    turn: np.ndarray,
    fps: float,
    start: np.ndarray | None = None,
    heading: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Root path on the floor ``(F, 3)`` and facing rotations ``(F, 4)`` from per-frame
    velocities in the facing frame ``(F, 2)`` (sideways x, forward z; units per second)
    and turning velocities ``(F,)`` (rad/s), the inverse of :func:`root_velocities`.

    The root starts at ``start`` (its height ignored; the origin by default) facing
    ``heading`` radians about +Y; the step from frame t to t + 1 is frame t's velocity
    turned by frame t's heading.
    """
    velocity = np.asarray(velocity, dtype=np.float64)
    frames = len(velocity)
    angle = heading + np.concatenate([[0.0], np.cumsum(np.asarray(turn, float)[:-1]) / fps])
    face = rot.about_y(angle)
    step = np.zeros((frames, 3))
    step[:, [0, 2]] = velocity / fps
    world_step = rot.apply(face, step)
    origin = np.zeros(3) if start is None else np.asarray(start, dtype=np.float64) * [1, 0, 1]
    root = origin + np.concatenate([np.zeros((1, 3)), np.cumsum(world_step[:-1], axis=0)])
    return root, face


def velocities(x: np.ndarray, fps: float) -> np.ndarray:
    """Finite-difference velocities along axis 0 (per second), same shape; frame 0 copies frame 1."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 2:
        return np.zeros_like(x)
    v = np.empty_like(x)
    v[1:] = (x[1:] - x[:-1]) * fps
    v[0] = v[1]
    return v


def resample_at(motion: Motion, frame_positions: np.ndarray, fps: float) -> Motion:
    """Frames at fractional source indices ``frame_positions (N,)`` (clamped to the clip),
    slerp for rotations and linear for translations, labelled with rate ``fps``."""
    t = np.clip(np.asarray(frame_positions, dtype=np.float64), 0.0, motion.num_frames - 1)
    i0 = np.clip(np.floor(t).astype(int), 0, max(motion.num_frames - 2, 0))
    i1 = np.minimum(i0 + 1, motion.num_frames - 1)
    w = (t - i0)[:, None]
    lrot = np.ascontiguousarray(motion.lrot, dtype=np.float64)
    a, b, d = kernels.slerp_ends(lrot, i0.astype(np.int64), i1.astype(np.int64))
    theta = np.arccos(np.minimum(np.abs(d), 1.0))  # numpy's: rot.slerp's bits
    lrot = kernels.slerp_mix(a, b, w, theta, d)
    lpos = motion.lpos[i0] * (1.0 - w[..., None]) + motion.lpos[i1] * w[..., None]
    return motion.replace(fps=float(fps), lrot=lrot, lpos=lpos)


def resample(motion: Motion, fps: float) -> Motion:
    """The motion at a new frame rate: slerp for rotations, linear for translations.

    Frame ``i`` of the result is the pose at time ``i / fps``; the result ends at the
    last new frame within the clip. Rates within 0.01% (30 vs 1/0.0333333) count as equal.
    """
    if not np.isfinite(fps) or fps <= 0:
        raise MotionError(f"target frame rate must be positive, got {fps}")
    if abs(fps - motion.fps) <= 1e-4 * fps or motion.num_frames < 2:
        return motion.replace(fps=float(fps))
    span = (motion.num_frames - 1) / motion.fps
    count = int(np.floor(span * fps + 1e-3)) + 1
    return resample_at(motion, np.arange(count) * (motion.fps / fps), fps)


def resample_count(motion: Motion, fps: float, num_frames: int) -> Motion:
    """Exactly ``num_frames`` frames at ``fps`` (frame ``i`` = time ``i / fps``, the last
    source frame held past the end). Brings a processed clip back onto a caller's timing."""
    if num_frames < 1:
        raise MotionError("need at least one frame")
    return resample_at(motion, np.arange(num_frames) * (motion.fps / fps), fps)

"""Fitting joint rotations to target positions: a motion on a skeleton whose joints follow
``(F, J, 3)`` targets as closely as rigid bones allow (the fast networks' output, marker
data). Vectorised over frames: each step loops over joints only, the rotation that aims a
joint's bones at their targets found for every frame at once (shortest swing, or Kabsch's
SVD for several bones).

Quaternions are (x, y, z, w) as in :mod:`motion.rotations`; positions ``(F, J, 3)``.
"""

from __future__ import annotations

import numpy as np

from motion import canonical as C
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1, keepdims=True)


def _translated_joints(skeleton: Skeleton) -> list[int]:
    """Joints whose translation follows the target: the root, and children of the root
    with position channels (the canonical Hips under its floor root)."""
    return [0] + [c for c in skeleton.children(0) if skeleton.has_position(c)]


def _bones(skeleton: Skeleton, translated: list[int]) -> list[list[tuple[int, list[int]]]]:
    """For each joint, the bones its rotation aims: ``(descendant, zero-length joints
    between)``. A child with a zero offset passes its own children up, so a CMU pelvis
    (three zero-offset children) still sees its legs and spine."""
    lengths = np.linalg.norm(skeleton.offsets, axis=-1)
    tiny = 1e-9 * max(float(lengths.max()), 1e-9)
    out: list[list[tuple[int, list[int]]]] = []
    for j in range(skeleton.num_joints):
        bones: list[tuple[int, list[int]]] = []
        stack = [(c, []) for c in skeleton.children(j) if c not in translated]
        while stack:
            c, between = stack.pop(0)
            if lengths[c] > tiny:
                bones.append((c, between))
            else:
                stack.extend((g, between + [c]) for g in skeleton.children(c))
        out.append(bones)
    return out


def _kabsch(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations ``(F, 4)`` minimising ``sum_k |R a_k - b_k|^2`` for ``a, b (F, K, 3)``
    (about the origin), and whether each was well determined ``(F,)`` (not all
    ``a_k`` on one line)."""
    h = np.einsum("fki,fkj->fij", a, b)
    u, s, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    flip = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    flip = np.where(flip == 0, 1.0, flip)
    d = np.ones(s.shape)
    d[:, 2] = flip
    m = (v * d[:, None, :]) @ np.swapaxes(u, -1, -2)
    ok = s[:, 1] > 1e-6 * np.maximum(s[:, 0], 1e-300)
    return rot.from_matrix(m), ok


def _fit_pass(
    targets: np.ndarray, skeleton: Skeleton, lrot_init: np.ndarray, translated: list[int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One top-down pass: each joint's rotation aims its bones at the target positions
    from where its parent put it. Returns ``lrot, grot (F, J, 4)``, ``gpos (F, J, 3)``."""
    frames, joints = targets.shape[:2]
    parents = skeleton.parents
    lrot = lrot_init.copy()
    grot = np.empty((frames, joints, 4))
    gpos = np.empty((frames, joints, 3))
    for j, bones in enumerate(_bones(skeleton, translated)):
        p = int(parents[j])
        parent_rot = rot.identity((frames,)) if p < 0 else grot[:, p]
        if j in translated:
            gpos[:, j] = targets[:, j]
        else:
            gpos[:, j] = gpos[:, p] + rot.apply(parent_rot, skeleton.offsets[j])
        g = rot.mul(parent_rot, lrot_init[:, j])
        if bones:
            rest = []
            for d, between in bones:
                chain = rot.identity((frames,))
                for k in between:
                    chain = rot.mul(chain, lrot_init[:, k])
                rest.append(rot.apply(rot.mul(g, chain), skeleton.offsets[d]))
            now = np.stack(rest, axis=1)
            wanted = targets[:, [d for d, _ in bones]] - gpos[:, j, None]
            # the shortest swing of the summed bone: exact for one bone, the fallback
            # for bones all on one line; several bones fix the twist too
            swing = rot.between(now.sum(axis=1), wanted.sum(axis=1))
            if len(bones) > 1:
                turn, ok = _kabsch(now, wanted)
                swing = np.where(ok[:, None], turn, swing)
            g = rot.mul(swing, g)
        grot[:, j] = g
        lrot[:, j] = rot.mul(rot.inv(parent_rot), g)
    return lrot, grot, gpos


def _subtrees(skeleton: Skeleton, translated: list[int]) -> list[list[int]]:
    """Descendants of each joint that move rigidly with it (translated joints excluded)."""
    below: list[list[int]] = [[] for _ in range(skeleton.num_joints)]
    for j in range(skeleton.num_joints - 1, 0, -1):
        if j in translated:
            continue
        p = int(skeleton.parents[j])
        below[p] = [j] + below[j] + below[p]
    return below


def _refine(
    gpos: np.ndarray, targets: np.ndarray, skeleton: Skeleton, translated: list[int]
) -> np.ndarray:
    """One top-down sweep of block coordinate descent on positions: each joint turns
    its subtree rigidly about itself to best match the targets (bone lengths kept)."""
    gpos = gpos.copy()
    for j, sub in enumerate(_subtrees(skeleton, translated)):
        if not sub:
            continue
        now = gpos[:, sub] - gpos[:, j, None]
        wanted = targets[:, sub] - gpos[:, j, None]
        if len(sub) == 1:  # one joint: aimed, as Kabsch would, at a fraction of its cost
            turn = rot.between(now[:, 0], wanted[:, 0])
        else:
            turn, _ = _kabsch(now, wanted)
        gpos[:, sub] = gpos[:, j, None] + rot.apply(turn[:, None], now)
    return gpos


def fit_positions(
    target_gpos: np.ndarray,
    skeleton: Skeleton,
    reference: Motion | None = None,
    iterations: int = 2,
    fps: float | None = None,
) -> Motion:
    """A motion on ``skeleton`` whose joints follow ``target_gpos (F, J, 3)``.

    Bone lengths are the skeleton's, exactly; positions are matched as well as rigid
    bones allow. The root (and a root child with position channels, e.g. the canonical
    Hips) takes its translation from the target. Going down the hierarchy, each joint
    turns by the shortest swing that aims its bone at the target, or, with several
    bones (pelvis, chest), by the rotation that best aligns them all (Kabsch). Twist
    comes from ``reference``'s local rotations when given (it must have the same
    skeleton and frame count), else it is zero relative to the rest pose; joints without
    bones (leaves) keep the reference's rotation or the identity. ``iterations`` sweeps
    of rigid subtree alignment refine the positions of noisy targets before the final
    pass. ``fps`` defaults to the reference's, else the canonical 30.
    """
    target_gpos = np.asarray(target_gpos, dtype=np.float64)
    joints = skeleton.num_joints
    if target_gpos.ndim != 3 or target_gpos.shape[1:] != (joints, 3):
        raise MotionError(
            f"target positions must be (frames, {joints}, 3), got {target_gpos.shape}"
        )
    if not np.all(np.isfinite(target_gpos)):
        raise MotionError("target positions contain NaN or infinity")
    frames = len(target_gpos)
    if frames == 0:
        raise MotionError("target positions have no frames")
    if reference is not None:
        if reference.skeleton.num_joints != joints or reference.num_frames != frames:
            raise MotionError("reference motion must have the same joints and frame count")
        lrot_init = rot.normalize(reference.lrot)
        fps = reference.fps if fps is None else fps
    else:
        lrot_init = rot.identity((frames, joints))
    fps = C.FPS if fps is None else float(fps)
    translated = _translated_joints(skeleton)

    lrot, grot, gpos = _fit_pass(target_gpos, skeleton, lrot_init, translated)
    if iterations > 0:
        for _ in range(iterations):
            gpos = _refine(gpos, target_gpos, skeleton, translated)
        lrot, grot, gpos = _fit_pass(gpos, skeleton, lrot_init, translated)

    lpos = np.repeat(skeleton.offsets[None], frames, axis=0)
    for j in translated:
        p = int(skeleton.parents[j])
        lpos[:, j] = (
            target_gpos[:, j]
            if p < 0
            else rot.apply(rot.inv(grot[:, p]), target_gpos[:, j] - gpos[:, p])
        )
    if reference is not None:
        lrot = np.where(_dot(lrot, reference.lrot) < 0, -lrot, lrot)
    else:
        lrot = rot.make_continuous(lrot)
    return Motion(skeleton, fps, lrot, lpos)

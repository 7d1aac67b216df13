"""Fitting joint rotations to target positions: a motion on a skeleton whose joints follow
``(F, J, 3)`` targets as closely as rigid bones allow (marker data: Dance with Melody).
Vectorised over frames: each step loops over joints only, the rotation that aims a
joint's bones at their targets found for every frame at once (shortest swing, or the best
rotation of several bones in Horn's quaternion form, solved in closed form).

Quaternions are (x, y, z, w) as in :mod:`motion.rotations`; positions ``(F, J, 3)``.
"""

from __future__ import annotations

import numpy as np

from motion import canonical as C
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton


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
    (about the origin), and whether each was well determined ``(F,)``: the covariance's
    second singular value above 1e-6 of its first (not all ``a_k``, or ``b_k``, on one
    line).

    Horn's quaternion form, solved in closed form for every frame at once (Theobald's
    QCP): the rotation is the eigenvector of the largest eigenvalue of a symmetric 4x4
    matrix built from the covariance; that eigenvalue is found by Newton's method on the
    characteristic polynomial from an upper bound, the eigenvector as a column of the
    adjugate. The same rotations as a batched 3x3 SVD (within 1e-8 where well determined)
    in about a third of the time."""
    h = np.einsum("fki,fkj->ijf", a, b)  # h[i, j] = sum_k a_i b_j, frames last
    (xx, xy, xz), (yx, yy, yz), (zx, zy, zz) = h
    n = np.array([
        [xx + yy + zz, yz - zy, zx - xz, xy - yx],
        [yz - zy, xx - yy - zz, xy + yx, zx + xz],
        [zx - xz, xy + yx, yy - xx - zz, yz + zy],
        [xy - yx, zx + xz, yz + zy, zz - xx - yy],
    ])  # fmt: skip
    n2 = np.einsum("ikf,kjf->ijf", n, n)
    p2 = np.einsum("ijf,ijf->f", n, n)  # traces of n^2, n^3, n^4
    p3 = np.einsum("ijf,ijf->f", n2, n)
    p4 = np.einsum("ijf,ijf->f", n2, n2)
    c2, c1, c0 = -p2 / 2, -p3 / 3, (p2 * p2 - 2 * p4) / 8  # n is traceless
    lam = 0.5 * (np.einsum("fki,fki->f", a, a) + np.einsum("fki,fki->f", b, b))
    for _ in range(50):  # from above, where the quartic is convex: monotone
        slope = (4 * lam * lam + 2 * c2) * lam + c1
        step = ((lam * lam + c2) * lam * lam + c1 * lam + c0) / np.where(slope > 0, slope, np.inf)
        lam = lam - step
        if np.all(np.abs(step) <= 1e-14 * np.abs(lam) + 1e-300):
            break
    q = _adjugate_column(n - lam * np.eye(4)[:, :, None])
    length = np.linalg.norm(q, axis=-1, keepdims=True)
    scale = np.max(np.abs(n), axis=(0, 1))[:, None] ** 3  # the adjugate's order
    # a largest eigenvalue twice over (e.g. no bones at all) leaves no single null vector
    q = np.where(length > 1e-12 * scale, q / np.where(length > 0, length, 1.0), [1.0, 0, 0, 0])
    cof2 = sum(
        (h[i1, j1] * h[i2, j2] - h[i1, j2] * h[i2, j1]) ** 2
        for i1, i2 in ((0, 1), (0, 2), (1, 2))
        for j1, j2 in ((0, 1), (0, 2), (1, 2))
    )
    ok = cof2 > 1e-12 * np.einsum("ijf,ijf->f", h, h) ** 2  # the second singular value
    return q[:, [1, 2, 3, 0]], ok


def _adjugate_column(m: np.ndarray) -> np.ndarray:
    """The longest column ``(F, 4)`` of the adjugate of symmetric 4x4 matrices ``m (4, 4,
    F)`` of rank 3: their null vectors. From the 2x2 minors of the top and bottom rows."""
    (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = m
    s0, s1, s2 = a00 * a11 - a10 * a01, a00 * a12 - a10 * a02, a00 * a13 - a10 * a03
    s3, s4, s5 = a01 * a12 - a11 * a02, a01 * a13 - a11 * a03, a02 * a13 - a12 * a03
    c5, c4, c3 = a22 * a33 - a32 * a23, a21 * a33 - a31 * a23, a21 * a32 - a31 * a22
    c2, c1, c0 = a20 * a33 - a30 * a23, a20 * a32 - a30 * a22, a20 * a31 - a30 * a21
    adj = np.array([
        [a11 * c5 - a12 * c4 + a13 * c3, -a01 * c5 + a02 * c4 - a03 * c3,
         a31 * s5 - a32 * s4 + a33 * s3, -a21 * s5 + a22 * s4 - a23 * s3],
        [-a10 * c5 + a12 * c2 - a13 * c1, a00 * c5 - a02 * c2 + a03 * c1,
         -a30 * s5 + a32 * s2 - a33 * s1, a20 * s5 - a22 * s2 + a23 * s1],
        [a10 * c4 - a11 * c2 + a13 * c0, -a00 * c4 + a01 * c2 - a03 * c0,
         a30 * s4 - a31 * s2 + a33 * s0, -a20 * s4 + a21 * s2 - a23 * s0],
        [-a10 * c3 + a11 * c1 - a12 * c0, a00 * c3 - a01 * c1 + a02 * c0,
         -a30 * s3 + a31 * s1 - a32 * s0, a20 * s3 - a21 * s1 + a22 * s0],
    ])  # fmt: skip  # adj[i, j]: the (j, i) cofactor
    longest = np.argmax(np.einsum("ijf,ijf->jf", adj, adj), axis=0)
    return np.take_along_axis(adj, longest[None, None], axis=1)[:, 0].T


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
        # one joint, or joints on one line: aimed by the shortest swing, as Kabsch would
        turn = rot.between(now.sum(axis=1), wanted.sum(axis=1))
        if len(sub) > 1:
            best, ok = _kabsch(now, wanted)
            turn = np.where(ok[:, None], best, turn)
        gpos[:, sub] = gpos[:, j, None] + rot.apply(turn[:, None], now)
    return gpos


def fit_positions(
    target_gpos: np.ndarray,
    skeleton: Skeleton,
    iterations: int = 2,
    fps: float | None = None,
) -> Motion:
    """A motion on ``skeleton`` whose joints follow ``target_gpos (F, J, 3)``.

    Bone lengths are the skeleton's, exactly; positions are matched as well as rigid
    bones allow. The root (and a root child with position channels, e.g. the canonical
    Hips) takes its translation from the target. Going down the hierarchy, each joint
    turns by the shortest swing that aims its bone at the target, or, with several
    bones (pelvis, chest), by the rotation that best aligns them all (:func:`_kabsch`). A
    single bone's twist is zero relative to the rest pose, and joints without bones
    (leaves) keep the identity. ``iterations`` sweeps of rigid subtree alignment refine
    the positions of noisy targets before the final pass. ``fps`` defaults to the
    canonical 30.
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
    return Motion(skeleton, fps, rot.make_continuous(lrot), lpos)

"""A skeleton's hierarchy and geometry as the rig mappers read them.

:class:`JointTree` answers topology and bone-length questions; :func:`complete_trunk` finds
chest, hips, spine and neck from the mapped limbs and head; :func:`hierarchy_problem` says
what is wrong with a mapping's order. The geometry helpers sample a clip's poses and tell
which way a body faces and which side a joint sits on.
"""

from __future__ import annotations

import numpy as np

from motion import kinematics as K
from motion import rotations as rot
from motion.rig_names import normalise_name
from motion.skeleton import Motion, Skeleton


class JointTree:
    """Topology and bone lengths of a skeleton, with the queries the mappers need."""

    def __init__(self, skeleton: Skeleton) -> None:
        self.parents = skeleton.parents
        n = skeleton.num_joints
        self.n = n
        self.children: list[list[int]] = [[] for _ in range(n)]
        for j in range(1, n):
            self.children[int(self.parents[j])].append(j)
        self.bone = np.linalg.norm(skeleton.offsets, axis=-1)
        self.bone[0] = 0.0
        self.end = np.zeros(n)
        for j, offs in skeleton.end_sites.items():
            self.end[j] = max(float(np.linalg.norm(o)) for o in offs) if offs else 0.0
        self.depth = np.zeros(n, dtype=int)
        for j in range(1, n):
            self.depth[j] = self.depth[self.parents[j]] + 1
        self.rotates = np.array(
            [any(c.endswith("rotation") for c in ch) for ch in skeleton.channels], dtype=bool
        )
        scale = float(self.bone.sum() + self.end.sum())
        self.tiny = 1e-4 * max(scale, 1e-9)  # bones shorter than this sit on their parent

    def is_ancestor(self, a: int, b: int) -> bool:
        """Whether ``a`` is ``b`` or above it."""
        while b > a:
            b = int(self.parents[b])
        return a == b

    def lca(self, *joints: int) -> int:
        out = joints[0]
        for b in joints[1:]:
            a = out
            while self.depth[a] > self.depth[b]:
                a = int(self.parents[a])
            while self.depth[b] > self.depth[a]:
                b = int(self.parents[b])
            while a != b:
                a, b = int(self.parents[a]), int(self.parents[b])
            out = a
        return out

    def path(self, top: int, bottom: int) -> list[int]:
        """Joints strictly below ``top`` down to ``bottom``, top first."""
        out = []
        while bottom != top and bottom >= 0:
            out.append(bottom)
            bottom = int(self.parents[bottom])
        return out[::-1]


def complete_trunk(
    tree: JointTree,
    names: tuple[str, ...],
    m: dict[str, int],
    frames: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict[str, int]:
    """Chest, hips, spine and neck from the limbs and head where not already named: the
    chest is where the arms meet (the joint below when that is a neck, as on a 3ds Max
    Biped), the hips where legs and chest meet. Spine and neck are the joints between
    hips and chest, chest and head, that let the clip's mapped joints be rebuilt best
    from the canonical skeleton (:func:`_landing_error` on the clip's ``frames``, world
    rotations and positions); without a clip, the first ones."""
    m = dict(m)
    arm = [m.get(f"Shoulder_{s}", m.get(f"UpperArm_{s}")) for s in ("L", "R")]
    if "Chest" not in m and None not in arm:
        chest = tree.lca(*arm)
        if chest in arm:
            chest = int(tree.parents[chest])
        if chest > 0 and "neck" in normalise_name(names[chest])[1] and "Head" in m:
            m.setdefault("Neck", chest)
            chest = int(tree.parents[chest])
        if chest >= 0:
            m["Chest"] = chest
    legs = [m.get(f"UpperLeg_{s}") for s in ("L", "R")]
    if "Hips" not in m and None not in legs and "Chest" in m:
        m["Hips"] = tree.lca(*legs, m["Chest"])
    hips, chest, head = m.get("Hips"), m.get("Chest"), m.get("Head")
    for name, top, bottom, others in (
        ("Spine", hips, chest, ("UpperLeg_L", "UpperLeg_R")),
        ("Neck", chest, head, ("Shoulder_L", "Shoulder_R", "UpperArm_L", "UpperArm_R")),
    ):
        if top is None or bottom is None or name in m:
            continue
        used = set(m.values())
        between = [j for j in tree.path(top, bottom)[:-1] if j not in used and tree.rotates[j]]
        if not between:
            continue
        siblings = [m[o] for o in others if o in m and tree.parents[m[o]] >= 0]
        siblings = [
            s for s in siblings if not any(tree.is_ancestor(t, s) for t in siblings if t != s)
        ]
        if frames is None or len(between) == 1:
            m[name] = between[0]
        else:
            errors = [_landing_error(tree, frames, top, [x, *siblings], x, bottom) for x in between]
            m[name] = between[int(np.argmin(np.round(errors, 6)))]
    return m


def _fit_residual(reference: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Per frame, the largest distance ``(N,)`` between vectors ``now (N, n, 3)`` and the
    best rotation of ``reference (n, 3)`` onto them (a swing for one vector)."""
    if len(reference) == 1:
        # a swing leaves only the change in length
        return np.abs(np.linalg.norm(reference[0]) - np.linalg.norm(now[:, 0], axis=-1))
    weights = np.linalg.norm(reference, axis=-1)
    cov = np.einsum("n,fni,nj->fij", weights, now, reference)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= d[..., None]
    fitted = np.einsum("fij,nj->fni", u @ vt, reference)
    return np.linalg.norm(fitted - now, axis=-1).max(axis=-1)


def _landing_error(
    tree: JointTree,
    frames: tuple[np.ndarray, np.ndarray],
    top: int,
    kids: list[int],
    x: int,
    below: int,
) -> float:
    """How far mapped joints would land from the clip's when ``x`` is mapped between ``top``
    and ``below``: what a rotation of ``top`` cannot do for its mapped children ``kids``
    through the joints in between, and what ``x`` cannot do for ``below``, as the joints
    in between hold their mean pose (mean over the frames of the worst child)."""
    grot, gpos = frames[0][::4], frames[1][::4]  # a coarse choice: 16 of the frames will do
    err = 0.0
    for j, children in ((top, kids), (x, [below])):
        now = rot.apply(rot.inv(grot[:, j])[:, None], gpos[:, children] - gpos[:, j, None])
        reference = now.mean(axis=0)
        keep = np.linalg.norm(reference, axis=-1) > tree.tiny
        if keep.any():
            err += float(_fit_residual(reference[keep], now[:, keep]).mean())
    return err


_ORDER = [
    ("Hips", "Spine"), ("Spine", "Chest"), ("Hips", "Chest"), ("Chest", "Neck"), ("Neck", "Head"),
    ("Chest", "Head"),
    *[(a, b) for s in ("L", "R") for a, b in (
        ("Hips", f"UpperLeg_{s}"), (f"UpperLeg_{s}", f"LowerLeg_{s}"),
        (f"LowerLeg_{s}", f"Foot_{s}"), (f"Foot_{s}", f"Toes_{s}"), ("Chest", f"Shoulder_{s}"),
        (f"Shoulder_{s}", f"UpperArm_{s}"), ("Chest", f"UpperArm_{s}"),
        (f"UpperArm_{s}", f"LowerArm_{s}"), (f"LowerArm_{s}", f"Hand_{s}"))],
]  # fmt: skip


def hierarchy_problem(
    skeleton: Skeleton, m: dict[str, int], tree: JointTree | None = None
) -> str | None:
    """What is wrong with a mapping's order in the hierarchy (a knee above its thigh, an
    arm not below the hips, one joint in two roles), or None."""
    tree = tree or JointTree(skeleton)
    names = skeleton.names
    if len(set(m.values())) != len(m):
        twice = [names[j] for j in set(m.values()) if list(m.values()).count(j) > 1]
        return f"joint {twice[0]!r} is mapped to two canonical joints"
    hips = m.get("Hips")
    if hips is not None:
        for k, v in m.items():
            if k != "joint_Root" and not tree.is_ancestor(hips, v):
                return f"mapped joint {names[v]!r} ({k}) is not below the hips"
    for a, b in _ORDER:
        if a in m and b in m and (m[a] == m[b] or not tree.is_ancestor(m[a], m[b])):
            return f"mapped joint {names[m[b]]!r} ({b}) is not below {names[m[a]]!r} ({a})"
    return None


def sample_indices(num_frames: int, count: int = 64) -> np.ndarray:
    """Up to ``count`` frame indices spread evenly over a clip."""
    return np.unique(np.linspace(0, num_frames - 1, min(count, num_frames)).round()).astype(int)


def sample_frames(
    skeleton: Skeleton, motion: Motion | None, count: int = 64
) -> tuple[np.ndarray, np.ndarray] | None:
    """World rotations ``(N, J, 4)`` and positions ``(N, J, 3)`` of up to ``count`` frames
    spread over the clip (:func:`sample_indices`), or None without one."""
    if motion is None or motion.num_frames == 0:
        return None
    idx = sample_indices(motion.num_frames, count)
    return K.fk(motion.lrot[idx], motion.lpos[idx], skeleton.parents)


def sample_poses(skeleton: Skeleton, frames: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Joint positions ``(N, J, 3)``: the rest pose, then the sampled frames."""
    rest = skeleton.rest_positions()[None]
    return rest if frames is None else np.concatenate([rest, frames[1]])


def sample_ends(skeleton: Skeleton, frames: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Where each joint's longest End Site is ``(N, J, 3)`` in the poses of
    :func:`sample_poses` (the joint itself where it has none)."""
    tip = np.zeros((skeleton.num_joints, 3))
    for j, offs in skeleton.end_sites.items():
        if offs:
            tip[j] = max(offs, key=lambda o: float(np.linalg.norm(o)))
    rest = (skeleton.rest_positions() + tip)[None]
    if frames is None:
        return rest
    return np.concatenate([rest, frames[1] + rot.apply(frames[0], tip)])


def normalised(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def facing(
    poses: np.ndarray, ends: np.ndarray, legs: list[dict[str, int]], up: np.ndarray
) -> np.ndarray:
    """Forward vectors ``(N, 3)`` across the body's up axis, as long as the cue is strong
    (in leg lengths): toes point forward (the leg's last joint past the ankle, else the
    ankle's End Site), knees bend forward."""
    fwd = np.zeros(poses.shape[:1] + (3,))
    for leg in legs:
        hip, knee, ankle = (
            poses[:, leg["UpperLeg"]],
            poses[:, leg["LowerLeg"]],
            poses[:, leg["Foot"]],
        )
        length = np.linalg.norm(knee - hip, axis=-1) + np.linalg.norm(ankle - knee, axis=-1)
        length = np.maximum(length, 1e-9)[:, None]
        tip = leg.get("tip", leg["Foot"])
        toes = poses[:, tip] if tip != leg["Foot"] else ends[:, tip]
        for v in (toes - ankle, 2.0 * (knee - 0.5 * (hip + ankle))):
            v = v - np.sum(v * up, axis=-1, keepdims=True) * up
            fwd += v / length
    return fwd


def side_votes(
    poses: np.ndarray, up: np.ndarray, fwd: np.ndarray, a: int, b: int
) -> tuple[float, float]:
    """How clearly joint ``a`` sits on the body's left of ``b`` (+1) or right (-1), and the
    strength of the facing cue it rests on (mean forward vector length, in leg lengths)."""
    strength = np.linalg.norm(fwd, axis=-1)
    left = normalised(np.cross(up, fwd))
    d = normalised(poses[:, a] - poses[:, b])
    vote = np.sum(d * left, axis=-1)
    w = strength
    if w.sum() < 1e-9:
        return 0.0, 0.0
    return float(np.sum(w * vote) / w.sum()), float(strength.mean())


def body_up(poses: np.ndarray, hips: int, chest: int) -> np.ndarray:
    return normalised(poses[:, chest] - poses[:, hips])

"""Any humanoid onto the canonical skeleton and back, rest-pose aware.

One mechanism for T-pose, A-pose, arms-down, the CMU "star" pose and rotated
joint frames: for each skeleton we find, per mapped joint, the world rotation
``tpose[j]`` that takes the joint from a *reference pose* into the canonical
T-pose (body frame first, then a swing of the joint's bone onto the template
direction). Motion then travels as world rotations relative to that T-pose:

    canonical global = source global * inv(source tpose)      (canonical tpose = I)
    target global    = canonical global * target tpose

The reference pose is the rest pose when it looks like a standing humanoid,
Bandai's standing pose for its rig (its rest lies along X), or else the clip's
most upright frame.

Joints between mapped joints (spine segments, a pelvis or waist bone, twist and
helper bones) make a mapped joint's bone point elsewhere than the joint's own
rotation says. So each such mapped joint carries a *correction*: the rotation
that takes its mapped children, as the reference pose places them in the joint's
frame, to where the joints in between place them now (the shortest swing for one
child, the best fit for several). On the way in the canonical rotation includes
it; on the way back it is taken out again, measured on the joints in between as
the clip to fit (``like``) poses them, or nothing when they hold the reference
pose, so the mapped joints land where the source puts them.

Which joint is which comes from :mod:`motion.rig_mapping` (names, else structure;
an explicit mapping overrides). Unmapped joints keep their own motion on the way
back. Everything runs on whole clips at once: loops go over joints, never frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from motion import canonical as C
from motion import kernels, rig_mapping, rig_tree
from motion import kinematics as K
from motion import rotations as rot
from motion.skeleton import Motion, Skeleton

__all__ = [
    "Rig", "body_frame", "from_canonical", "make_rig", "retarget", "to_canonical",
]  # fmt: skip

_CANONICAL_REST = C.SKELETON.rest_positions()


def body_frame(gpos: np.ndarray, m: dict[str, int]) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` whose columns are the body's left, up and forward axes."""
    up = gpos[..., m["Chest"], :] - gpos[..., m["Hips"], :]
    across = (gpos[..., m["UpperLeg_L"], :] - gpos[..., m["UpperLeg_R"], :]) + (
        gpos[..., m["UpperArm_L"], :] - gpos[..., m["UpperArm_R"], :]
    )
    up = up / np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-9)
    fwd = np.cross(across, up)
    fwd = fwd / np.maximum(np.linalg.norm(fwd, axis=-1, keepdims=True), 1e-9)
    left = np.cross(up, fwd)
    return np.stack([left, up, fwd], axis=-1)


def _pose_score(gpos: np.ndarray, m: dict[str, int]) -> np.ndarray:
    """How much poses ``(..., J, 3)`` look like standing with straight legs (higher is better),
    measured in each pose's own body frame."""
    frame = body_frame(gpos, m)

    def direction(a: str, b: str) -> np.ndarray:
        v = gpos[..., m[b], :] - gpos[..., m[a], :]
        v = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)
        return np.einsum("...ji,...j->...i", frame, v)  # into body axes

    score = 0.0
    for s in ("L", "R"):
        score = score - direction(f"UpperLeg_{s}", f"LowerLeg_{s}")[..., 1]
        score = score - direction(f"LowerLeg_{s}", f"Foot_{s}")[..., 1]
        sign = 1.0 if s == "L" else -1.0
        arm = direction(f"UpperArm_{s}", f"LowerArm_{s}")
        # arms out sideways or hanging down are both fine references; forward/up is not
        score = score + 0.5 * np.maximum(sign * arm[..., 0], -arm[..., 1])
    return score


def _rest_is_usable(rest: np.ndarray, m: dict[str, int]) -> bool:
    """Whether rest positions ``(J, 3)`` stand like a humanoid (legs straight down)."""
    if np.linalg.norm(rest[m["Chest"]] - rest[m["Hips"]]) < 1e-6:
        return False
    return bool(_pose_score(rest, m) > 3.5)  # 4 for straight legs; arms add up to 1


@dataclass(frozen=True)
class _Correction:
    """A mapped joint whose mapped children hang from it through joints in between."""

    joint: int  # the mapped joint
    paths: tuple[tuple[int, ...], ...]  # per mapped child: the joints from it up to below joint
    reference: np.ndarray  # (n, 3) where the reference pose puts them, in the joint's frame
    weights: np.ndarray  # (n,)


def _fit_rotation(reference: np.ndarray, now: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 4)`` taking the vectors ``reference (n, 3)`` onto ``now (F, n, 3)``:
    the shortest swing for one vector, the weighted least-squares fit (Kabsch) for more."""
    if len(reference) == 1:
        return rot.between(reference[0], now[:, 0])
    cov = np.einsum("n,fni,nj->fij", weights, now, reference)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= d[..., None]
    return rot.from_matrix(u @ vt)


def _correction(c: _Correction, lrot: np.ndarray, lpos: np.ndarray) -> np.ndarray:
    """The correction's rotation ``(F, 4)`` for a clip's local rotations and translations:
    only the joints in between matter, and where they do not move it is computed once."""
    now = []
    for path in c.paths:  # child first: its place in the frame of the joint at the top
        v = lpos[:, path[0]]
        for k in path[1:]:
            v = rot.apply(lrot[:, k], v) + lpos[:, k]
        now.append(v)
    now = np.stack(now, axis=1)
    if not (now != now[:1]).any():
        return np.broadcast_to(_fit_rotation(c.reference, now[:1], c.weights), (len(now), 4))
    return _fit_rotation(c.reference, now, c.weights)


def _world_rotations(lrot: np.ndarray, parents: np.ndarray, needed: np.ndarray) -> np.ndarray:
    """World rotations ``(F, J, 4)`` of the ``needed`` joints (whose parents are needed
    too); the others are left zero."""
    lrot = np.ascontiguousarray(lrot, dtype=np.float64)
    return kernels.world_rotations(lrot, np.asarray(parents, dtype=np.int64), needed)


@dataclass(frozen=True)
class Rig:
    """What retargeting needs to know about one skeleton."""

    skeleton: Skeleton
    mapping: dict[str, int]  # canonical joint -> this skeleton's joint index
    tpose: np.ndarray  # (J, 4) world rotation from reference pose into the canonical T-pose
    reference_lrot: np.ndarray  # (J, 4) local rotations of the reference pose
    leg_length: float  # hip-to-ankle along the bones
    reference: str  # "rest", "registered" or "frame <i>"
    up: np.ndarray = field(default_factory=lambda: rot.IDENTITY.copy())  # file's world -> Y-up
    method: str = "names"  # how the mapping was found: "names", "structure" or "given"
    confidence: float = 1.0
    convention: str = ""  # the naming convention the names matched
    corrections: tuple[_Correction, ...] = ()
    bones: np.ndarray | None = None  # (J, 3) the clip's own translations where they differ

    @property
    def bone_vectors(self) -> np.ndarray:
        """Each joint's translation from its parent as the clip holds it: its position
        channels' median where it has animated ones, else its offset (:func:`bone_vectors`)."""
        return self.skeleton.offsets if self.bones is None else self.bones

    @property
    def up_axis(self) -> str:
        """The file's up axis: ``"Y"``, or ``"Z"`` etc. for a file turned upright on the way in."""
        axis = rot.apply(rot.inv(self.up), np.array([0.0, 1.0, 0.0]))
        i = int(np.argmax(np.abs(axis)))
        return ("-" if axis[i] < 0 else "") + "XYZ"[i]

    @property
    def unmapped(self) -> list[str]:
        """This skeleton's joints that have no canonical counterpart."""
        used = set(self.mapping.values())
        return [n for i, n in enumerate(self.skeleton.names) if i not in used]

    @property
    def height(self) -> float:
        """Standing height in the file's units: the canonical one scaled by leg length."""
        return C.body_height() * self.leg_length / C.leg_length()

    def mapping_by_name(self) -> dict[str, str]:
        return {k: self.skeleton.names[v] for k, v in self.mapping.items()}

    def report(self) -> dict:
        """The mapping, how it was found and how sure it is, for JSON answers."""
        out = {
            "mapping": self.mapping_by_name(),
            "method": self.method,
            "confidence": self.confidence,
        }
        if self.convention:
            out["convention"] = self.convention
        return out


def make_rig(
    skeleton: Skeleton,
    motion: Motion | None = None,
    mapping: dict[str, str] | None = None,
    reference_lrot: np.ndarray | None = None,
) -> Rig:
    """Map ``skeleton`` and compute its T-pose rotations.

    The reference pose is ``reference_lrot`` if given, else the rest pose when it is
    a usable standing pose, else Bandai's standing pose for its rig, else the most
    upright of the clip's frames (64 spread over ``motion``).
    """
    frames, sampled = None, np.zeros(0, dtype=int)
    if motion is not None and motion.num_frames:
        sampled = rig_tree.sample_indices(motion.num_frames)
        frames = K.fk(motion.lrot[sampled], motion.lpos[sampled], skeleton.parents)
    found = rig_mapping.find_mapping(skeleton, motion, mapping, frames=frames)
    m = found.joints
    nj = skeleton.num_joints
    bones, moving = bone_vectors(skeleton, motion, m["Hips"])
    rest = skeleton.with_offsets(bones).rest_positions()
    height = float(max(np.ptp(rest, axis=0).max(), 1e-6))
    how = "given"
    if reference_lrot is None:
        if _rest_is_usable(rest, m):
            reference_lrot, how = rot.identity((nj,)), "rest"
        elif skeleton.names == C.JOINTS:  # Bandai's own rig: its rest pose lies along X
            reference_lrot, how = C.BANDAI_REFERENCE_LROT, "registered"
        elif frames is not None:
            best = int(np.argmax(_pose_score(frames[1], m)))
            reference_lrot, how = motion.lrot[sampled[best]].copy(), f"frame {sampled[best]}"
        else:
            reference_lrot, how = rot.identity((nj,)), "rest"
    reference_lrot = rot.normalize(reference_lrot)
    if frames is not None and (how == "rest" or how.startswith("frame")):
        # joints between mapped ones hold their usual pose: some rigs keep a pelvis or
        # neck bone turned throughout, and a clip retargeted without its own clip to
        # follow (``from_canonical`` without ``like``) must land mapped joints there too
        between = _joints_between(skeleton, m)
        if len(between):
            reference_lrot = reference_lrot.copy()
            reference_lrot[between] = rot.mean(motion.lrot[sampled][:, between])
    grot, gpos = K.fk(reference_lrot, bones, skeleton.parents)
    tpose = _tpose(skeleton, m, grot, gpos, height)
    leg = 0.0
    for s in ("L", "R"):
        path = _chain(skeleton.parents, m[f"UpperLeg_{s}"], m[f"Foot_{s}"])
        leg += sum(np.linalg.norm(bones[k]) for k in path) / 2.0
    return Rig(
        skeleton,
        m,
        tpose,
        reference_lrot,
        max(float(leg), 1e-9),
        how,
        _upright(rest, m, frames),
        found.method,
        found.confidence,
        found.convention,
        _corrections(skeleton, m, grot, gpos, height, moving),
        None if bones is skeleton.offsets else bones,
    )


def bone_vectors(
    skeleton: Skeleton, motion: Motion | None, hips: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's translation from its parent as ``motion`` holds it ``(J, 3)``, and
    which joints' translations move ``(J,)``. A joint with position channels (Brekel's
    exporter writes them on every joint, Blender's on many) may hold other values than its
    OFFSET, and move them: its median over the clip stands for its offset then (the
    ``hips`` and the joints above them keep theirs: their translations are the path).
    Without such joints: the offsets, as is."""
    offsets = skeleton.offsets
    moving = np.zeros(skeleton.num_joints, dtype=bool)
    if motion is None or motion.num_frames == 0:
        return offsets, moving
    path = set(_chain(skeleton.parents, -1, hips))
    inner = np.array(
        [j not in path and skeleton.has_position(j) for j in range(skeleton.num_joints)]
    )
    if not inner.any():
        return offsets, moving
    lpos = motion.lpos[:, inner]
    tiny = 1e-6 * skeleton.height()
    if np.abs(lpos - offsets[inner]).max() <= tiny / 2:  # the common case, in one pass
        return offsets, moving
    moving[inner] = np.ptp(lpos, axis=0).max(axis=-1) > tiny
    median = np.median(lpos, axis=0)
    if not moving.any() and np.abs(median - offsets[inner]).max() <= tiny:
        return offsets, moving
    bones = offsets.copy()
    bones[inner] = median
    return bones, moving


def _tpose(
    skeleton: Skeleton, m: dict[str, int], grot: np.ndarray, gpos: np.ndarray, height: float
) -> np.ndarray:
    """Per joint ``(J, 4)``, the world rotation from the reference pose (``grot``, ``gpos``)
    into the canonical T-pose: into the body's axes, then a swing of the joint's bone (to
    its mapped child, else to its fingers or toe tip) onto the template direction; joints
    with neither swing with their parent."""
    frame = body_frame(gpos, m)
    to_body = rot.from_matrix(frame.T)  # world -> canonical axes
    templates = C.template_directions()
    names, bones, targets = [], [], []
    for cname in C.JOINTS:
        if cname not in m:
            continue
        j = m[cname]
        child = C.MAIN_CHILD.get(cname)
        while child is not None and child not in m:  # skip unmapped canonical joints
            child = C.MAIN_CHILD.get(child)
        if child is not None and cname in templates:
            bone = gpos[m[child]] - gpos[j]
            if np.linalg.norm(bone) > 1e-6 * height:
                names.append(cname)
                bones.append(frame.T @ bone)
                targets.append(_CANONICAL_REST[C.INDEX[child]] - _CANONICAL_REST[C.INDEX[cname]])
                continue
        if cname in _TIP_TEMPLATES:  # hand, or foot without toes
            tip = _tip_vector(skeleton, j, grot, gpos, height)
            if tip is not None:
                names.append(cname)
                bones.append(frame.T @ tip)
                targets.append(_TIP_TEMPLATES[cname])
    swings = dict(zip(names, rot.between(np.array(bones), np.array(targets)), strict=True))
    mapped = [cname for cname in C.JOINTS if cname in m]
    for cname in mapped:  # parents first
        if cname not in swings:  # leaf or degenerate bone: move rigidly with the parent's swing
            parent = C.PARENTS[C.INDEX[cname]]
            swings[cname] = (
                swings.get(C.JOINTS[parent], rot.IDENTITY) if parent >= 0 else rot.IDENTITY
            )
    joints = [m[cname] for cname in mapped]
    tpose = rot.identity((skeleton.num_joints,))
    swing = np.array([swings[cname] for cname in mapped])
    tpose[joints] = rot.mul(swing, rot.mul(to_body, grot[joints]))  # all joints in one product
    return tpose


def _joints_between(skeleton: Skeleton, m: dict[str, int]) -> np.ndarray:
    """Unmapped joints on the paths from the hips to mapped joints."""
    hips = m["Hips"]
    used = set(m.values())
    out = set()
    for j in used:
        for k in _chain(skeleton.parents, hips, j)[1:]:
            if k not in used:
                out.add(k)
    return np.array(sorted(out), dtype=int)


def _mapped_children(cname: str, m: dict[str, int]) -> list[str]:
    """The canonical children of ``cname`` that are mapped, looking through unmapped ones."""
    out = []
    for ci in np.nonzero(C.PARENTS == C.INDEX[cname])[0]:
        child = C.JOINTS[ci]
        out += [child] if child in m else _mapped_children(child, m)
    return out


def _corrections(
    skeleton: Skeleton,
    m: dict[str, int],
    grot: np.ndarray,
    gpos: np.ndarray,
    height: float,
    moving: np.ndarray | None = None,
) -> tuple[_Correction, ...]:
    """A correction for each mapped joint with a mapped child below joints that can move,
    or on the end of translations that move (``moving``, :func:`bone_vectors`)."""
    movable = np.array([len(ch) > 0 for ch in skeleton.channels])
    moving = np.zeros(skeleton.num_joints, dtype=bool) if moving is None else moving
    tiny = 1e-6 * height
    out = []
    for cname, j in m.items():
        if cname == "joint_Root":
            continue
        children = [m[c] for c in _mapped_children(cname, m)]
        paths = [tuple(_chain(skeleton.parents, j, k)) for k in children]  # child first
        turning = any(movable[list(p[1:])].any() for p in paths if len(p) > 1)
        if not turning and not any(moving[list(p)].any() for p in paths):
            continue
        ref = rot.apply(rot.inv(grot[j]), gpos[children] - gpos[j])
        lengths = np.linalg.norm(ref, axis=-1)
        keep = lengths > tiny
        if keep.any():
            kept = tuple(p for p, k in zip(paths, keep, strict=True) if k)
            out.append(_Correction(j, kept, ref[keep], lengths[keep]))
    return tuple(out)


def _upright(
    rest: np.ndarray, m: dict[str, int], frames: tuple[np.ndarray, np.ndarray] | None
) -> np.ndarray:
    """Rotation taking the file's world to Y-up: identity unless the body stands along
    another axis (Z-up exports of 3ds Max and Blender). A rest pose that stands must
    stand along it and the clip's ``frames`` (world rotations, positions) too: Bandai's
    rest lies along X in a Y-up world, and a Y-up clip of someone lying down stands along
    no axis in its rest pose's direction. A rest pose that does not stand (rotated joint
    frames) leaves it to the clip."""
    spine = rest[m["Chest"]] - rest[m["Hips"]]
    length = np.linalg.norm(spine)
    standing_rest = length > 1e-9 and _rest_is_usable(rest, m)
    axis = np.zeros(3)
    if standing_rest:
        spine = spine / length
        i = int(np.argmax(np.abs(spine)))
        if i == 1 or abs(spine[i]) < 0.9:
            return rot.IDENTITY.copy()
        axis[i] = np.sign(spine[i])
        if frames is None:
            return rot.between(axis, np.array([0.0, 1.0, 0.0]))
    elif frames is None:
        return rot.IDENTITY.copy()
    gpos = frames[1]
    ups = gpos[:, m["Chest"]] - gpos[:, m["Hips"]]
    ups /= np.maximum(np.linalg.norm(ups, axis=-1, keepdims=True), 1e-9)
    if not standing_rest:
        mean = ups.mean(axis=0)
        i = int(np.argmax(np.abs(mean)))
        if i == 1:
            return rot.IDENTITY.copy()
        axis[i] = np.sign(mean[i])
    if float(np.mean(ups @ axis)) < 0.7:
        return rot.IDENTITY.copy()
    return rot.between(axis, np.array([0.0, 1.0, 0.0]))


_TIP_TEMPLATES = {
    "Hand_L": np.array([1.0, 0.0, 0.0]),
    "Hand_R": np.array([-1.0, 0.0, 0.0]),
    "Foot_L": C.OFFSETS[C.INDEX["Toes_L"]],
    "Foot_R": C.OFFSETS[C.INDEX["Toes_R"]],
}


def _tip_vector(
    skeleton: Skeleton, j: int, grot: np.ndarray, gpos: np.ndarray, height: float
) -> np.ndarray | None:
    """World vector from joint ``j`` to the mean of its descendants and End Sites
    (fingers for a hand, the toe End Site for a foot), or None if it has none."""
    below = np.zeros(skeleton.num_joints, dtype=bool)
    below[j] = True
    for k in range(j + 1, skeleton.num_joints):
        below[k] = below[skeleton.parents[k]]
    points = [gpos[k] for k in np.nonzero(below)[0] if k != j]
    for d in np.nonzero(below)[0]:
        for off in skeleton.end_sites.get(int(d), ()):
            points.append(gpos[d] + rot.apply(grot[d], np.asarray(off)))
    if not points:
        return None
    tip = np.mean(points, axis=0) - gpos[j]
    return tip if np.linalg.norm(tip) > 1e-4 * height else None


def _chain(parents: np.ndarray, top: int, bottom: int) -> list[int]:
    """Joints on the path below ``top`` down to ``bottom`` (whose offsets add up to it),
    bottom first."""
    out = []
    j = bottom
    while j != top and j >= 0:
        out.append(j)
        j = int(parents[j])
    return out


# --------------------------------------------------------------------------- transfer


def _canonical_sources(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """The mapped canonical joints (indices into C.JOINTS, root excluded) and, for every
    canonical joint but the root, which of them gives its world rotation: its own or, if
    unmapped, its nearest mapped canonical ancestor's (index into the first array)."""
    mapped = [ci for ci in range(1, len(C.JOINTS)) if C.JOINTS[ci] in rig.mapping]
    slot = {ci: i for i, ci in enumerate(mapped)}
    source = np.zeros(len(C.JOINTS), dtype=int)
    for ci in range(1, len(C.JOINTS)):
        source[ci] = slot[ci] if ci in slot else source[C.PARENTS[ci]]
    return np.array(mapped), source[1:]


def to_canonical(motion: Motion, rig: Rig | None = None, fps: float | None = C.FPS) -> Motion:
    """The motion on the canonical skeleton (at ``fps``; ``None`` keeps the clip's rate)."""
    rig = rig or make_rig(motion.skeleton, motion)
    parents = motion.skeleton.parents
    frames = motion.num_frames
    mapped, source = _canonical_sources(rig)
    joints = np.array([rig.mapping[C.JOINTS[ci]] for ci in mapped])
    grot = _world_rotations(motion.lrot, parents, K.with_ancestors(parents, joints))
    hips = rig.mapping["Hips"]
    hips_pos = motion.lpos[:, hips]  # in the world: up the chain above the hips
    p = int(parents[hips])
    while p >= 0:
        hips_pos = motion.lpos[:, p] + rot.apply(motion.lrot[:, p], hips_pos)
        p = int(parents[p])
    # the T-pose rotations do not depend on the world's orientation, so turning a Z-up
    # world upright is one rotation of every global
    g = rot.mul(rig.up, grot[:, joints])
    for c in rig.corrections:
        i = int(np.nonzero(joints == c.joint)[0][0])
        g[:, i] = rot.mul(g[:, i], _correction(c, motion.lrot, motion.lpos))
    canon = rot.mul(g, rot.inv(rig.tpose[joints]))
    cgrot = rot.identity((frames, len(C.JOINTS)))  # the canonical root stays unrotated
    cgrot[:, 1:] = canon[:, source]
    clrot = K.local_from_global(cgrot, C.PARENTS)
    clrot[:, 0] = rot.IDENTITY
    clpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    clpos[:, 0] = 0.0  # on the floor; the hips carry the path
    clpos[:, 1] = rot.apply(rig.up, hips_pos) * (C.leg_length() / rig.leg_length)
    out = Motion(C.SKELETON, motion.fps, rot.make_continuous(clrot), clpos)
    if fps is not None:
        out = K.resample(out, fps)
    return out


def from_canonical(canon: Motion, rig: Rig, like: Motion | None = None) -> Motion:
    """A canonical motion back on ``rig``'s skeleton.

    With ``like`` (the clip it came from), the result has ``like``'s frame rate and
    frame count, and joints without a canonical counterpart keep ``like``'s motion;
    otherwise they hold the rig's reference pose and the canonical rate is kept.
    """
    sk = rig.skeleton
    parents = sk.parents
    if like is not None:
        if abs(canon.fps - like.fps) > 1e-4 * like.fps or canon.num_frames != like.num_frames:
            canon = K.resample_count(canon, like.fps, like.num_frames)
        else:  # same timing (30 vs 1/0.0333333 counts as the same): nothing to resample
            canon = canon.replace(fps=like.fps)
    frames = canon.num_frames
    if like is not None:
        own_lrot, own_lpos = like.lrot.copy(), like.lpos.copy()
    else:
        own_lrot = np.repeat(rig.reference_lrot[None], frames, axis=0)
        own_lpos = np.repeat(rig.bone_vectors[None], frames, axis=0)
        own_lpos[:, 0] = 0.0
    mapped, _ = _canonical_sources(rig)
    joints = np.array([rig.mapping[C.JOINTS[ci]] for ci in mapped])
    cgrot = _world_rotations(canon.lrot, C.PARENTS, K.with_ancestors(C.PARENTS, mapped))
    target = rot.mul(cgrot[:, mapped], rig.tpose[joints])  # world rotations of mapped joints
    if like is not None:
        # joints in between keep the clip's motion: take out what they add to the bones
        for c in rig.corrections:
            i = int(np.nonzero(joints == c.joint)[0][0])
            target[:, i] = rot.mul(target[:, i], rot.inv(_correction(c, own_lrot, own_lpos)))
    roots = parents < 0
    own_lrot[:, roots] = rot.mul(rig.up, own_lrot[:, roots])  # into the upright world
    own_lpos[:, roots] = rot.apply(rig.up, own_lpos[:, roots])
    # world rotations are needed only down to the mapped joints' parents
    needed = K.with_ancestors(parents, parents[joints][parents[joints] >= 0])
    slot = np.full(sk.num_joints, -1)
    slot[joints] = np.arange(len(joints))
    grot = np.empty((frames, sk.num_joints, 4))
    grot[:, 0] = own_lrot[:, 0] if slot[0] < 0 else target[:, slot[0]]
    for level, above in K.levels(parents):  # a level of the hierarchy at a time
        level, above = level[needed[level]], above[needed[level]]
        own = slot[level] < 0
        grot[:, level[own]] = rot.mul(grot[:, above[own]], own_lrot[:, level[own]])
        grot[:, level[~own]] = target[:, slot[level[~own]]]
    lrot, lpos = own_lrot, own_lpos
    inner = parents[joints] >= 0
    lrot[:, joints[~inner]] = target[:, ~inner]
    lrot[:, joints[inner]] = rot.mul(rot.inv(grot[:, parents[joints[inner]]]), target[:, inner])
    hips = rig.mapping["Hips"]
    hips_world = canon.lpos[:, C.INDEX["Hips"]] * (rig.leg_length / C.leg_length())
    above = _chain(parents, -1, int(parents[hips]))[::-1] if parents[hips] >= 0 else []
    if above:
        gpos = lpos[:, above[0]]
        for j in above[1:]:
            gpos = gpos + rot.apply(grot[:, parents[j]], lpos[:, j])
        lpos[:, hips] = rot.apply(rot.inv(grot[:, parents[hips]]), hips_world - gpos)
    else:
        lpos[:, hips] = hips_world
    back = rot.inv(rig.up)  # and back into the file's world
    lrot[:, roots] = rot.mul(back, lrot[:, roots])
    lpos[:, roots] = rot.apply(back, lpos[:, roots])
    return Motion(sk, canon.fps, rot.make_continuous(lrot), lpos)


def retarget(
    motion: Motion,
    onto: Motion | Skeleton,
    mapping: dict[str, str] | None = None,
    onto_mapping: dict[str, str] | None = None,
) -> Motion:
    """``motion`` performed by another skeleton (``onto``'s, at ``motion``'s frame rate)."""
    src = make_rig(motion.skeleton, motion, mapping)
    target_motion = onto if isinstance(onto, Motion) else None
    target_sk = onto.skeleton if isinstance(onto, Motion) else onto
    dst = make_rig(target_sk, target_motion, onto_mapping)
    canon = to_canonical(motion, src, fps=None)
    return from_canonical(canon, dst).replace(fps=motion.fps)

"""Any humanoid onto the canonical skeleton and back, rest-pose aware.

One mechanism for T-pose, A-pose, arms-down, the CMU "star" pose and rotated
joint frames: for each skeleton we find, per mapped joint, the world rotation
``tpose[j]`` that takes the joint from a *reference pose* into the canonical
T-pose (body frame first, then a swing of the joint's bone onto the template
direction). Motion then travels as world rotations relative to that T-pose:

    canonical global = source global * inv(source tpose)      (canonical tpose = I)
    target global    = canonical global * target tpose

The reference pose is the rest pose when it looks like a standing humanoid,
a registered pose for known rigs whose rest pose does not (Bandai lies flat
along X), or else the clip's most upright frame.

Joints are mapped by name (Bandai, CMU 31, DAZ/Poser 43, cgspeed 3ds Max,
Mixamo ``mixamorig:``, 3ds Max Biped ``Bip01``, Unreal ``thigh_l``, generic
``LeftUpLeg``/``Spine1``) plus the hierarchy: limbs by name, then hips, chest
and neck as the common ancestors of the limbs. A caller may pass an explicit
mapping. Unmapped joints keep their own motion on the way back.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from motion import canonical as C
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton

REQUIRED = (
    "Hips", "Chest", "Head",
    "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R", "LowerArm_R", "Hand_R",
    "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R",
)  # fmt: skip

# Limb joints by name. Names are normalised first: lower case, namespaces
# ("mixamorig:") and rig prefixes ("Bip01 ", "DEF-") removed, side words turned
# into a marker; patterns then match the side-free rest.
_LIMB_PATTERNS: dict[str, tuple[str, ...]] = {
    "UpperLeg": ("upleg", "upperleg", "thigh", "hip", "femur", "legupper"),
    "LowerLeg": ("leg", "lowerleg", "knee", "shin", "calf", "tibia", "leglower"),
    "Foot": ("foot", "ankle"),
    "Toes": ("toebase", "toe", "toes", "ball", "toe0", "toes0"),
    "Shoulder": ("shoulder", "clavicle", "collar", "clav"),
    "UpperArm": ("arm", "upperarm", "shldr", "shoulder", "humerus", "armupper"),
    "LowerArm": ("forearm", "lowerarm", "elbow", "armlower", "radius"),
    "Hand": ("hand", "wrist"),
}
_SKIP_WORDS = ("twist", "roll", "end", "nub", "site", "ik", "pole", "target", "helper", "jnt")


def normalise_name(name: str) -> tuple[str, str]:
    """``(side, core)`` of a joint name: side ``"L"``, ``"R"`` or ``""``; core lower case."""
    n = name.strip()
    n = n.split(":")[-1]  # namespaces, mixamorig:
    n = re.sub(r"^(bip0*\d+|def|mixamorig\d*|character\d*|cc_base|rig)[\s_\-.]+", "", n, flags=re.I)
    n = re.sub(r"(?<=[a-z])(?=[A-Z])", "_", n)  # camelCase -> camel_Case
    low = n.lower()
    tokens = [t for t in re.split(r"[\s_\-.]+", low) if t]
    side = ""
    rest: list[str] = []
    for t in tokens:
        if t in ("l", "left", "lft") and not side:
            side = "L"
        elif t in ("r", "right", "rgt", "rt") and not side:
            side = "R"
        else:
            rest.append(t)
    core = "".join(rest)
    if not side:
        m = re.match(r"^(left|right)(.+)$", core) or re.match(r"^([lr])([a-z].+)$", core)
        if m:
            side = "L" if m.group(1) in ("left", "l") else "R"
            core = m.group(2)
    return side, core


def _is_helper(core: str) -> bool:
    return any(w in core for w in _SKIP_WORDS)


def _match(core: str, pattern: str) -> bool:
    # "leg" must not match "upleg"; allow trailing digits (toe0, neck01)
    return re.fullmatch(pattern + r"\d*", core) is not None


def find_mapping(skeleton: Skeleton, explicit: dict[str, str] | None = None) -> dict[str, int]:
    """Canonical joint name -> index of the skeleton's joint that plays it.

    ``explicit`` maps joint names either way (``{"mixamorig:Hips": "Hips"}`` or
    ``{"Hips": "mixamorig:Hips"}``); its entries override the automatic ones.
    Raises ``MotionError`` (kind ``"unusable"``) listing the canonical joints it
    could not find.
    """
    names = skeleton.names
    parents = skeleton.parents
    found: dict[str, int] = {}
    if explicit:
        for a, b in explicit.items():
            if a in C.INDEX and b in names:
                found[a] = names.index(b)
            elif b in C.INDEX and a in names:
                found[b] = names.index(a)
            else:
                raise MotionError(
                    f"mapping entry {a!r}: {b!r} names no canonical joint and joint of this file",
                    kind="unusable",
                )
    if list(names) == list(C.JOINTS):
        auto = {n: i for i, n in enumerate(names)}
    else:
        auto = _auto_mapping(skeleton)
    for k, v in auto.items():
        if k not in found and v not in found.values():
            found[k] = v
    missing = [j for j in REQUIRED if j not in found]
    if missing:
        raise MotionError(
            "cannot map the skeleton onto the canonical humanoid: no joint found for "
            + ", ".join(missing)
            + " (pass a 'mapping' of joint names)",
            kind="unusable",
            unmapped=missing,
        )
    # every mapped joint must sit below the mapped hips
    hips = found["Hips"]
    for k, v in found.items():
        if k != "joint_Root" and not _is_ancestor(parents, hips, v):
            raise MotionError(
                f"mapped joint {names[v]!r} ({k}) is not below the hips", kind="unusable"
            )
    return found


def _ancestors(parents: np.ndarray, j: int) -> list[int]:
    out = []
    while j >= 0:
        out.append(j)
        j = int(parents[j])
    return out


def _is_ancestor(parents: np.ndarray, a: int, b: int) -> bool:
    return a in _ancestors(parents, b)


def _auto_mapping(skeleton: Skeleton) -> dict[str, int]:
    names = skeleton.names
    parents = skeleton.parents
    info = [normalise_name(n) for n in names]
    out: dict[str, int] = {}

    def candidates(kind: str, side: str) -> list[int]:
        pats = _LIMB_PATTERNS[kind]
        hits = []
        for rank, pat in enumerate(pats):
            for j, (s, core) in enumerate(info):
                if s == side and not _is_helper(core) and _match(core, pat):
                    hits.append((rank, j))
        return [j for _, j in sorted(hits)]

    def descendants_first(root: int, pool: list[int]) -> int | None:
        best = None
        for j in pool:
            if j != root and _is_ancestor(parents, root, j):
                depth = len(_ancestors(parents, j))
                if best is None or depth < best[0]:
                    best = (depth, j)
        return None if best is None else best[1]

    def chain_anchor(middle: str, top: str, side: str) -> tuple[int | None, int | None]:
        """The knee (elbow) and its thigh (upper arm): the middle joint anchors a limb."""
        middles, tops = candidates(middle, side), candidates(top, side)
        mid = next(
            (k for k in middles if any(t != k and _is_ancestor(parents, t, k) for t in tops)),
            middles[0] if middles else None,
        )
        if mid is None:
            return None, None
        upper = _nearest_ancestor_in(parents, mid, tops)
        return (upper if upper is not None else _non_helper_parent(parents, info, mid)), mid

    for side in ("L", "R"):
        thigh, knee = chain_anchor("LowerLeg", "UpperLeg", side)
        if knee is not None:
            out[f"LowerLeg_{side}"] = knee
            if thigh is not None:
                out[f"UpperLeg_{side}"] = thigh
            foot = descendants_first(knee, candidates("Foot", side))
            if foot is not None:
                out[f"Foot_{side}"] = foot
                toe = descendants_first(foot, candidates("Toes", side))
                if toe is not None:
                    out[f"Toes_{side}"] = toe
        upper, elbow = chain_anchor("LowerArm", "UpperArm", side)
        if elbow is not None:
            out[f"LowerArm_{side}"] = elbow
            if upper is not None:
                out[f"UpperArm_{side}"] = upper
                clavicles = [c for c in candidates("Shoulder", side) if c != upper]
                clav = _nearest_ancestor_in(parents, upper, clavicles)
                if clav is not None:
                    out[f"Shoulder_{side}"] = clav
            hand = descendants_first(elbow, candidates("Hand", side))
            if hand is not None:
                out[f"Hand_{side}"] = hand
    # trunk from the hierarchy: hips = common ancestor of the thighs, chest = of the arms
    if "UpperLeg_L" in out and "UpperLeg_R" in out:
        hips = _common_ancestor(parents, out["UpperLeg_L"], out["UpperLeg_R"])
        out["Hips"] = hips
    arm_l = out.get("Shoulder_L", out.get("UpperArm_L"))
    arm_r = out.get("Shoulder_R", out.get("UpperArm_R"))
    heads = [j for j, (s, core) in enumerate(info) if not s and re.fullmatch(r"head\d*", core)]
    if arm_l is not None and arm_r is not None:
        chest = _common_ancestor(parents, arm_l, arm_r)
        if "neck" in info[chest][1] and parents[chest] >= 0:  # Biped hangs clavicles off the neck
            out["Neck"] = chest
            chest = int(parents[chest])
        out["Chest"] = chest
        heads = [h for h in heads if _is_ancestor(parents, chest, h) and h != chest]
        if heads:
            head = min(heads, key=lambda h: len(_ancestors(parents, h)))
            out["Head"] = head
            if "Neck" not in out and parents[head] != chest:
                out["Neck"] = int(parents[head])
        hips = out.get("Hips")
        if hips is not None and _is_ancestor(parents, hips, chest) and parents[chest] != hips:
            out["Spine"] = int(parents[chest])
    return out


def _nearest_ancestor_in(parents: np.ndarray, j: int, pool: list[int]) -> int | None:
    for a in _ancestors(parents, int(parents[j])) if parents[j] >= 0 else []:
        if a in pool:
            return a
    return None


def _non_helper_parent(parents: np.ndarray, info: list[tuple[str, str]], j: int) -> int | None:
    p = int(parents[j])
    while p >= 0 and _is_helper(info[p][1]):
        p = int(parents[p])
    return p if p >= 0 else None


def _common_ancestor(parents: np.ndarray, a: int, b: int) -> int:
    anc = set(_ancestors(parents, a))
    for j in _ancestors(parents, b):
        if j in anc and j not in (a, b):
            return j
    return 0


# --------------------------------------------------------------------------- reference pose

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


def _rest_is_usable(skeleton: Skeleton, m: dict[str, int]) -> bool:
    rest = skeleton.rest_positions()
    if np.linalg.norm(rest[m["Chest"]] - rest[m["Hips"]]) < 1e-6:
        return False
    return bool(_pose_score(rest, m) > 3.5)  # 4 for straight legs; arms add up to 1


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

    def mapping_by_name(self) -> dict[str, str]:
        return {k: self.skeleton.names[v] for k, v in self.mapping.items()}


def make_rig(
    skeleton: Skeleton,
    motion: Motion | None = None,
    mapping: dict[str, str] | None = None,
    reference_lrot: np.ndarray | None = None,
) -> Rig:
    """Map ``skeleton`` and compute its T-pose rotations.

    The reference pose is ``reference_lrot`` if given, else the rest pose when it is
    a usable standing pose, else a registered pose for a known rig, else the most
    upright frame of ``motion``.
    """
    m = find_mapping(skeleton, mapping)
    nj = skeleton.num_joints
    how = "given"
    if reference_lrot is None:
        if _rest_is_usable(skeleton, m):
            reference_lrot, how = rot.identity((nj,)), "rest"
        elif (reg := _registered_reference(skeleton)) is not None:
            reference_lrot, how = reg, "registered"
        elif motion is not None:
            step = max(1, motion.num_frames // 200)
            sub = motion.lrot[::step]
            gpos = K.fk(sub, skeleton.offsets[None], skeleton.parents)[1]
            best = int(np.argmax(_pose_score(gpos, m)))
            reference_lrot, how = sub[best].copy(), f"frame {best * step}"
        else:
            reference_lrot, how = rot.identity((nj,)), "rest"
    reference_lrot = rot.normalize(reference_lrot)
    grot, gpos = K.fk(reference_lrot, skeleton.offsets, skeleton.parents)
    frame = body_frame(gpos, m)
    to_body = rot.from_matrix(frame.T)  # world -> canonical axes
    templates = C.template_directions()
    tpose = rot.identity((nj,))
    swings: dict[str, np.ndarray] = {}
    for cname in C.JOINTS:
        if cname not in m:
            continue
        j = m[cname]
        swing = None
        child = C.MAIN_CHILD.get(cname)
        while child is not None and child not in m:  # skip unmapped canonical joints
            child = C.MAIN_CHILD.get(child)
        if child is not None and cname in templates:
            bone = gpos[m[child]] - gpos[j]
            if np.linalg.norm(bone) > 1e-6 * max(skeleton.height(), 1e-6):
                swing = rot.between(
                    frame.T @ bone,
                    _CANONICAL_REST[C.INDEX[child]] - _CANONICAL_REST[C.INDEX[cname]],
                )
        if swing is None and cname in _TIP_TEMPLATES:  # hand, or foot without toes
            tip = _tip_vector(skeleton, j, grot, gpos)
            if tip is not None:
                swing = rot.between(frame.T @ tip, _TIP_TEMPLATES[cname])
        if swing is None:  # leaf or degenerate bone: move rigidly with the parent's swing
            parent = C.PARENTS[C.INDEX[cname]]
            swing = swings.get(C.JOINTS[parent], rot.IDENTITY) if parent >= 0 else rot.IDENTITY
        swings[cname] = swing
        tpose[j] = rot.mul(swing, rot.mul(to_body, grot[j]))
    leg = 0.0
    for s in ("L", "R"):
        path = _chain(skeleton.parents, m[f"UpperLeg_{s}"], m[f"Foot_{s}"])
        leg += sum(np.linalg.norm(skeleton.offsets[k]) for k in path) / 2.0
    up = _upright(skeleton, m, motion)
    return Rig(skeleton, m, tpose, reference_lrot, max(float(leg), 1e-9), how, up)


def _upright(skeleton: Skeleton, m: dict[str, int], motion: Motion | None) -> np.ndarray:
    """Rotation taking the file's world to Y-up: identity unless the rest pose stands along
    another axis (Z-up exports of 3ds Max and Blender) and the motion stands along it too.
    Both must agree: Bandai's rest pose lies along X in a Y-up world, and a Y-up clip of
    someone lying down stands along no axis in its rest pose's direction."""
    rest = skeleton.rest_positions()
    spine = rest[m["Chest"]] - rest[m["Hips"]]
    length = np.linalg.norm(spine)
    if length < 1e-9:
        return rot.IDENTITY.copy()
    spine = spine / length
    i = int(np.argmax(np.abs(spine)))
    if i == 1 or abs(spine[i]) < 0.9:
        return rot.IDENTITY.copy()
    axis = np.zeros(3)
    axis[i] = np.sign(spine[i])
    if motion is None:
        if not _rest_is_usable(skeleton, m):
            return rot.IDENTITY.copy()
    else:
        step = max(1, motion.num_frames // 200)
        gpos = K.fk(motion.lrot[::step], motion.lpos[::step], skeleton.parents)[1]
        ups = gpos[:, m["Chest"]] - gpos[:, m["Hips"]]
        ups /= np.maximum(np.linalg.norm(ups, axis=-1, keepdims=True), 1e-9)
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
    skeleton: Skeleton, j: int, grot: np.ndarray, gpos: np.ndarray
) -> np.ndarray | None:
    """World vector from joint ``j`` to the mean of its descendants and End Sites
    (fingers for a hand, the toe End Site for a foot), or None if it has none."""
    points = [
        gpos[d] for d in range(j + 1, skeleton.num_joints) if _is_ancestor(skeleton.parents, j, d)
    ]
    for d in [j] + [
        k for k in range(j + 1, skeleton.num_joints) if _is_ancestor(skeleton.parents, j, k)
    ]:
        for off in skeleton.end_sites.get(d, ()):
            points.append(gpos[d] + rot.apply(grot[d], np.asarray(off)))
    if not points:
        return None
    tip = np.mean(points, axis=0) - gpos[j]
    return tip if np.linalg.norm(tip) > 1e-4 * skeleton.height() else None


def _chain(parents: np.ndarray, top: int, bottom: int) -> list[int]:
    """Joints on the path below ``top`` down to ``bottom`` (whose offsets add up to it)."""
    out = []
    j = bottom
    while j != top and j >= 0:
        out.append(j)
        j = int(parents[j])
    return out


# Known rigs whose rest pose is not a standing humanoid: a reference pose each.
_REGISTRY: list[tuple[tuple[str, ...], np.ndarray, np.ndarray]] = []


def register_reference(skeleton: Skeleton, reference_lrot: np.ndarray) -> None:
    """Remember a standing reference pose for rigs with these joint names and offsets."""
    _REGISTRY.append((skeleton.names, skeleton.offsets.copy(), np.asarray(reference_lrot)))


def _registered_reference(skeleton: Skeleton) -> np.ndarray | None:
    if skeleton.names == C.JOINTS:  # Bandai's own rig (the canonical one has a usable rest)
        return C.BANDAI_REFERENCE_LROT
    for names, offsets, ref in _REGISTRY:
        if names == skeleton.names:
            scale = max(np.abs(offsets[2:]).max(), 1e-9)
            if np.abs(offsets[2:] - skeleton.offsets[2:]).max() < 0.02 * scale:
                return ref
    return None


# --------------------------------------------------------------------------- transfer


def to_canonical(motion: Motion, rig: Rig | None = None, fps: float | None = C.FPS) -> Motion:
    """The motion on the canonical skeleton (at ``fps``; ``None`` keeps the clip's rate)."""
    rig = rig or make_rig(motion.skeleton, motion)
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    # the T-pose rotations do not depend on the world's orientation, so turning a Z-up
    # world upright is one rotation of every global
    grot, gpos = rot.mul(rig.up, grot), rot.apply(rig.up, gpos)
    frames = motion.num_frames
    cgrot = rot.identity((frames, len(C.JOINTS)))
    for ci, cname in enumerate(C.JOINTS):
        if ci == 0:  # the canonical root stays on the floor, unrotated; the hips carry the path
            continue
        if cname in rig.mapping:
            j = rig.mapping[cname]
            cgrot[:, ci] = rot.mul(grot[:, j], rot.inv(rig.tpose[j]))
        elif ci > 0:
            cgrot[:, ci] = cgrot[:, C.PARENTS[ci]]
    clrot = K.local_from_global(cgrot, C.PARENTS)
    clrot[:, 0] = rot.IDENTITY
    scale = C.leg_length() / rig.leg_length
    hips = gpos[:, rig.mapping["Hips"]] * scale
    clpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    clpos[:, 0] = 0.0
    clpos[:, 1] = hips
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
    if like is not None:
        canon = K.resample_count(canon, like.fps, like.num_frames)
    frames = canon.num_frames
    cgrot, cgpos = K.fk(canon.lrot, canon.lpos, C.PARENTS)
    if like is not None:
        own_lrot = like.lrot
        own_lpos = like.lpos
    else:
        own_lrot = np.repeat(rig.reference_lrot[None], frames, axis=0)
        own_lpos = np.repeat(sk.offsets[None], frames, axis=0)
        own_lpos[:, 0] = 0.0
    roots = sk.parents < 0
    own_lrot, own_lpos = own_lrot.copy(), own_lpos.copy()
    own_lrot[:, roots] = rot.mul(rig.up, own_lrot[:, roots])  # into the upright world
    own_lpos[:, roots] = rot.apply(rig.up, own_lpos[:, roots])
    by_joint = {v: k for k, v in rig.mapping.items()}
    grot = np.empty((frames, sk.num_joints, 4))
    gpos = np.empty((frames, sk.num_joints, 3))
    lrot = np.empty_like(grot)
    lpos = own_lpos.copy()
    hips = rig.mapping["Hips"]
    hips_world = cgpos[:, C.INDEX["Hips"]] * (rig.leg_length / C.leg_length())
    for j in range(sk.num_joints):
        p = int(sk.parents[j])
        cname = by_joint.get(j)
        if cname is not None and cname != "joint_Root":
            grot[:, j] = rot.mul(cgrot[:, C.INDEX[cname]], rig.tpose[j])
            lrot[:, j] = grot[:, j] if p < 0 else rot.mul(rot.inv(grot[:, p]), grot[:, j])
        else:
            lrot[:, j] = own_lrot[:, j]
            grot[:, j] = lrot[:, j] if p < 0 else rot.mul(grot[:, p], lrot[:, j])
        if j == hips:
            lpos[:, j] = (
                hips_world if p < 0 else rot.apply(rot.inv(grot[:, p]), hips_world - gpos[:, p])
            )
        gpos[:, j] = lpos[:, j] if p < 0 else gpos[:, p] + rot.apply(grot[:, p], lpos[:, j])
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

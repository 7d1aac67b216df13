"""Which joint of a skeleton plays which canonical joint: by name where the names say, by
structure where they do not.

**Names.** A table per naming convention (:data:`CONVENTIONS`) matched case-insensitively
after any common prefix (a namespace such as ``mixamorig:``, a skeleton name such as
``Skeleton1_``): the convention that names the most joints wins. Where no table names the
limbs, generic word patterns do (``thigh``, ``upleg``, ``forearm``, ``clavicle``..., sides
from ``L``/``Left``/``.L``/``_l``). Tables and patterns name the limbs and the head; the
trunk follows from the hierarchy: the chest is where the arms meet, the hips where the legs
meet the spine, the spine joint the chest's parent, the neck the head's.

**Structure.** Without usable names: short side branches (fingers, toes, twist and helper
leaves, eyes, props) are pruned until a few long chains remain; the assignment of five of
them to legs, arms and head that fits a humanoid best wins: the legs' junction below the
other three's, legs hanging down from the hips and the head up from the chest in the rest
pose and the clip's frames, pairs of similar length. Within each limb the knee (elbow) is
the split of the chain into two bones of similar length whose in-between joints do not bend;
the hand is where fingers branch. Left and right come from the facing, measured on the
feet (toes point forward) and the knees (they bend forward), then from name sides. Names
weigh in as evidence throughout. A rig whose sides nothing tells apart is refused with
:class:`~motion.errors.AmbiguousRigError`, which says how to pass a ``mapping``.

Over 600 lines in one module: conventions, name words, the hierarchy and the geometry
are evidence for one search over one tree (``_Tree``), and each kind of evidence is
weighed against the others there.
"""

from __future__ import annotations

import functools
import itertools
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from motion import canonical as C
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import AmbiguousRigError, MotionError
from motion.skeleton import Motion, Skeleton

REQUIRED = (
    "Hips", "Chest", "Head",
    "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R", "LowerArm_R", "Hand_R",
    "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R",
)  # fmt: skip
LEG_ROLES = ("UpperLeg", "LowerLeg", "Foot", "Toes")
ARM_ROLES = ("Shoulder", "UpperArm", "LowerArm", "Hand")
MAX_STRUCTURE_JOINTS = 2000  # pruning is quadratic at worst; real rigs have a few hundred


@dataclass(frozen=True)
class RigMapping:
    """Canonical joint name -> joint index, how it was found and how sure we are.

    ``method``: ``"names"`` (a naming convention or word patterns), ``"structure"``
    (hierarchy, rest-pose and clip geometry, bone lengths; names as evidence) or
    ``"given"`` (the caller's ``mapping`` named every required joint). ``confidence``
    in [0, 1]: how clearly the rig's own geometry agrees (names) or how far the chosen
    reading beats the next best (structure).
    """

    joints: dict[str, int]
    method: str
    confidence: float
    convention: str = ""


# --------------------------------------------------------------------------- conventions

# Templates: {L} -> L/R, {l} -> l/r, {Left} -> Left/Right (case is ignored when matching).
# Each names the limbs and the head (and the hips where the hierarchy would not find them).
CONVENTIONS: dict[str, dict[str, tuple[str, ...]]] = {
    "MotionBuilder / CMU / Mixamo / Vicon Shogun": {
        "Head": ("Head",),
        "UpperLeg": ("{Left}UpLeg",), "LowerLeg": ("{Left}Leg",), "Foot": ("{Left}Foot",),
        "Toes": ("{Left}ToeBase",), "Shoulder": ("{Left}Shoulder",), "UpperArm": ("{Left}Arm",),
        "LowerArm": ("{Left}ForeArm",), "Hand": ("{Left}Hand",),
    },
    "Unity humanoid / VRM": {
        "Head": ("Head",),
        "UpperLeg": ("{Left}UpperLeg",), "LowerLeg": ("{Left}LowerLeg",), "Foot": ("{Left}Foot",),
        "Toes": ("{Left}Toes",), "Shoulder": ("{Left}Shoulder",),
        "UpperArm": ("{Left}UpperArm",), "LowerArm": ("{Left}LowerArm",), "Hand": ("{Left}Hand",),
    },
    "VRoid (VRM)": {
        "Hips": ("J_Bip_C_Hips",), "Head": ("J_Bip_C_Head",),
        "UpperLeg": ("J_Bip_{L}_UpperLeg",), "LowerLeg": ("J_Bip_{L}_LowerLeg",),
        "Foot": ("J_Bip_{L}_Foot",), "Toes": ("J_Bip_{L}_ToeBase",),
        "Shoulder": ("J_Bip_{L}_Shoulder",), "UpperArm": ("J_Bip_{L}_UpperArm",),
        "LowerArm": ("J_Bip_{L}_LowerArm",), "Hand": ("J_Bip_{L}_Hand",),
    },
    "Xsens MVN": {
        "Hips": ("Pelvis",), "Head": ("Head",),
        "UpperLeg": ("{Left}UpperLeg",), "LowerLeg": ("{Left}LowerLeg",), "Foot": ("{Left}Foot",),
        "Toes": ("{Left}Toe",), "Shoulder": ("{Left}Shoulder",), "UpperArm": ("{Left}UpperArm",),
        "LowerArm": ("{Left}ForeArm",), "Hand": ("{Left}Hand",),
    },
    "cgspeed 3ds Max (CMU)": {
        "Head": ("Head",),
        "UpperLeg": ("{Left}Hip",), "LowerLeg": ("{Left}Knee",), "Foot": ("{Left}Ankle",),
        "Toes": ("{Left}Toe",), "Shoulder": ("{Left}Collar",), "UpperArm": ("{Left}Shoulder",),
        "LowerArm": ("{Left}Elbow",), "Hand": ("{Left}Wrist",),
    },
    "DAZ/Poser, Second Life classic": {
        "Head": ("head",),
        "UpperLeg": ("{l}Thigh",), "LowerLeg": ("{l}Shin",), "Foot": ("{l}Foot",),
        "Toes": ("{l}Toe",), "Shoulder": ("{l}Collar",), "UpperArm": ("{l}Shldr",),
        "LowerArm": ("{l}ForeArm",), "Hand": ("{l}Hand",),
    },
    "Daz Genesis 8": {
        "Head": ("head",),
        "UpperLeg": ("{l}ThighBend",), "LowerLeg": ("{l}Shin",), "Foot": ("{l}Foot",),
        "Toes": ("{l}Toe",), "Shoulder": ("{l}Collar",), "UpperArm": ("{l}ShldrBend",),
        "LowerArm": ("{l}ForearmBend",), "Hand": ("{l}Hand",),
    },
    "Daz Genesis 9": {
        "Head": ("head",),
        "UpperLeg": ("{l}_thigh",), "LowerLeg": ("{l}_shin",), "Foot": ("{l}_foot",),
        "Toes": ("{l}_toes",), "Shoulder": ("{l}_shoulder",), "UpperArm": ("{l}_upperarm",),
        "LowerArm": ("{l}_forearm",), "Hand": ("{l}_hand",),
    },
    "Reallusion CC/iClone": {
        "Hips": ("CC_Base_Hip",), "Head": ("CC_Base_Head",),
        "UpperLeg": ("CC_Base_{L}_Thigh",), "LowerLeg": ("CC_Base_{L}_Calf",),
        "Foot": ("CC_Base_{L}_Foot",), "Toes": ("CC_Base_{L}_ToeBase",),
        "Shoulder": ("CC_Base_{L}_Clavicle",), "UpperArm": ("CC_Base_{L}_Upperarm",),
        "LowerArm": ("CC_Base_{L}_Forearm",), "Hand": ("CC_Base_{L}_Hand",),
    },
    "Maya _JNT": {
        "Hips": ("hips_JNT",), "Head": ("head_JNT",),
        "UpperLeg": ("{l}_upleg_JNT",), "LowerLeg": ("{l}_leg_JNT",), "Foot": ("{l}_foot_JNT",),
        "Toes": ("{l}_toebase_JNT",), "Shoulder": ("{l}_shoulder_JNT",),
        "UpperArm": ("{l}_arm_JNT",), "LowerArm": ("{l}_forearm_JNT",), "Hand": ("{l}_hand_JNT",),
    },
    "Unreal / MB-Lab": {
        "Hips": ("pelvis",), "Head": ("head",),
        "UpperLeg": ("thigh_{l}",), "LowerLeg": ("calf_{l}",), "Foot": ("foot_{l}",),
        "Toes": ("ball_{l}", "toes_{l}"), "Shoulder": ("clavicle_{l}",),
        "UpperArm": ("upperarm_{l}",), "LowerArm": ("lowerarm_{l}",), "Hand": ("hand_{l}",),
    },
    "Blender Rigify": {
        "Head": ("head",),
        "UpperLeg": ("thigh.{L}",), "LowerLeg": ("shin.{L}",), "Foot": ("foot.{L}",),
        "Toes": ("toe.{L}",), "Shoulder": ("shoulder.{L}",), "UpperArm": ("upper_arm.{L}",),
        "LowerArm": ("forearm.{L}",), "Hand": ("hand.{L}",),
    },
    "3ds Max Biped": {
        "Hips": ("Pelvis",), "Head": ("Head",),
        "UpperLeg": ("{L} Thigh",), "LowerLeg": ("{L} Calf",), "Foot": ("{L} Foot",),
        "Toes": ("{L} Toe0",), "Shoulder": ("{L} Clavicle",), "UpperArm": ("{L} UpperArm",),
        "LowerArm": ("{L} Forearm",), "Hand": ("{L} Hand",),
    },
    "OptiTrack Motive": {
        "Hips": ("Hip",), "Head": ("Head",),
        "UpperLeg": ("{L}Thigh",), "LowerLeg": ("{L}Shin",), "Foot": ("{L}Foot",),
        "Toes": ("{L}Toe",), "Shoulder": ("{L}Shoulder",), "UpperArm": ("{L}UArm",),
        "LowerArm": ("{L}FArm",), "Hand": ("{L}Hand",),
    },
    "Vicon Plug-in Gait": {
        "Hips": ("Pelvis",), "Head": ("Head",),
        "UpperLeg": ("{L}Femur",), "LowerLeg": ("{L}Tibia",), "Foot": ("{L}Foot",),
        "Toes": ("{L}Toes",), "Shoulder": ("{L}Clavicle",), "UpperArm": ("{L}Humerus",),
        "LowerArm": ("{L}Radius",), "Hand": ("{L}Hand",),
    },
    "Kinect v2": {  # joints are named by where they sit: ShoulderLeft turns the upper arm
        "Hips": ("SpineBase",), "Head": ("Head",),
        "UpperLeg": ("Hip{Left}",), "LowerLeg": ("Knee{Left}",), "Foot": ("Ankle{Left}",),
        "Toes": ("Foot{Left}",), "UpperArm": ("Shoulder{Left}",), "LowerArm": ("Elbow{Left}",),
        "Hand": ("Wrist{Left}",),
    },
    "Second Life (Bento)": {
        "Hips": ("mPelvis",), "Head": ("mHead",),
        "UpperLeg": ("mHip{Left}",), "LowerLeg": ("mKnee{Left}",), "Foot": ("mAnkle{Left}",),
        "Toes": ("mFoot{Left}",), "Shoulder": ("mCollar{Left}",),
        "UpperArm": ("mShoulder{Left}",), "LowerArm": ("mElbow{Left}",), "Hand": ("mWrist{Left}",),
    },
}  # fmt: skip

_SIDE_WORDS = {"{L}": ("L", "R"), "{l}": ("l", "r"), "{Left}": ("Left", "Right")}
_PREFIX_SEPARATORS = ":_ |.-"


def _expand(template: str, side: str) -> str:
    for token, (left, right) in _SIDE_WORDS.items():
        template = template.replace(token, left if side == "L" else right)
    return template.lower()


def _expand_table(table: dict[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
    out = {}
    for role, templates in table.items():
        for side in ("L", "R") if "{" in templates[0] else ("",):
            out[f"{role}_{side}" if side else role] = tuple(_expand(t, side) for t in templates)
    return out


_EXPANDED = {name: _expand_table(table) for name, table in CONVENTIONS.items()}


def _name_suffixes(name: str) -> list[tuple[str, str]]:
    """``(prefix, rest)`` splits of a lower-cased name at every separator, whole name first."""
    low = name.strip().lower()
    out = [("", low)]
    for i, ch in enumerate(low):
        if ch in _PREFIX_SEPARATORS and i + 1 < len(low):
            out.append((low[: i + 1], low[i + 1 :]))
    return out


def match_convention(names: tuple[str, ...]) -> tuple[str, dict[str, int]]:
    """The naming convention that names most of these joints, and what it names
    (canonical joint -> index; limbs, head, and the hips where the table has them)."""
    by_rest: dict[str, list[tuple[str, int]]] = {}
    for j, n in enumerate(names):
        for prefix, rest in _name_suffixes(n):
            by_rest.setdefault(rest, []).append((prefix, j))
    best: tuple[int, str, dict[str, int]] = (0, "", {})
    for convention, table in _EXPANDED.items():
        hits: dict[str, list[tuple[str, int]]] = {}
        for key, alternatives in table.items():
            for t in alternatives:
                if found := by_rest.get(t):
                    hits[key] = found
                    break
        prefixes: dict[str, int] = {}
        for found in hits.values():
            for prefix in {p for p, _ in found}:
                prefixes[prefix] = prefixes.get(prefix, 0) + 1
        if not prefixes:
            continue
        prefix = max(prefixes, key=lambda p: (prefixes[p], -len(p)))
        joints = {}
        for key, found in hits.items():
            js = [j for p, j in found if p == prefix]
            if js:
                joints[key] = js[0]
        if len(joints) > best[0]:
            best = (len(joints), convention, joints)
    return best[1], best[2]


# --------------------------------------------------------------------------- word patterns

# Limb joints by word. Names are normalised first: lower case, namespaces ("mixamorig:")
# and rig decorations ("Bip01 ", "DEF-", "_JNT") removed, side words turned into a marker;
# patterns then match the side-free rest.
_LIMB_PATTERNS: dict[str, tuple[str, ...]] = {
    "UpperLeg": ("upleg", "upperleg", "thigh", "thighbend", "hip", "femur", "legupper"),
    "LowerLeg": ("leg", "lowerleg", "knee", "shin", "calf", "tibia", "leglower"),
    "Foot": ("foot", "ankle"),
    "Toes": ("toebase", "toe", "toes", "ball", "toe0", "toes0"),
    "Shoulder": ("shoulder", "clavicle", "collar", "clav"),
    "UpperArm": ("arm", "upperarm", "uparm", "shldr", "shldrbend", "shoulder", "humerus",
                 "armupper"),
    "LowerArm": ("forearm", "lowerarm", "forearmbend", "elbow", "armlower", "radius"),
    "Hand": ("hand", "wrist"),
}  # fmt: skip
_HELPER_WORDS = ("twist", "roll", "end", "nub", "site", "ik", "pole", "target", "helper",
                 "share", "prop", "weapon", "attach", "socket", "null", "dummy", "ctrl")  # fmt: skip
_DECORATION_PREFIX = re.compile(
    r"^(bip0*\d+|def|mixamorig\d*|character\d*|cc_base|rig|j_bip_[clr]|skeleton\d*)[\s_\-.:]+",
    re.I,
)
_DECORATION_SUFFIX = re.compile(r"[\s_\-.]+(jnt|joint|jx|bind|bn|bone|def|skin)$", re.I)


@functools.lru_cache(maxsize=4096)
def normalise_name(name: str) -> tuple[str, str]:
    """``(side, core)`` of a joint name: side ``"L"``, ``"R"`` or ``""``; core lower case."""
    n = name.strip().split(":")[-1]  # namespaces, mixamorig:
    n = _DECORATION_SUFFIX.sub("", _DECORATION_PREFIX.sub("", n))
    n = re.sub(r"(?<=[a-z])(?=[A-Z])", "_", n)  # camelCase -> camel_Case
    tokens = [t for t in re.split(r"[\s_\-.]+", n.lower()) if t]
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


def is_helper(name: str) -> bool:
    """Whether a joint's name says it is a twist, roll, end, IK or prop bone."""
    _, core = normalise_name(name)
    return any(w in core for w in _HELPER_WORDS)


@functools.lru_cache(maxsize=4096)
def _pattern_rank(core: str, role: str) -> int | None:
    """Index of the first of ``role``'s patterns the core matches ("leg" must not match
    "upleg"; trailing digits are allowed: toe0, neck01), or None."""
    for rank, pattern in enumerate(_LIMB_PATTERNS[role]):
        if re.fullmatch(pattern + r"\d*", core):
            return rank
    return None


def _word_roles(names: tuple[str, ...]) -> list[tuple[str, set[str], bool]]:
    """Per joint: its name's side, the limb roles its words fit, and whether it is a helper."""
    out = []
    for n in names:
        side, core = normalise_name(n)
        helper = any(w in core for w in _HELPER_WORDS)
        roles = set()
        if not helper:
            roles = {r for r in _LIMB_PATTERNS if _pattern_rank(core, r) is not None}
            if re.fullmatch(r"(head|skull)\d*", core):
                roles.add("Head")
        out.append((side, roles, helper))
    return out


def _pattern_limbs(tree: _Tree, names: tuple[str, ...]) -> dict[str, int]:
    """Limbs and head by word patterns, each limb anchored on its knee (elbow)."""
    words = _word_roles(names)
    out: dict[str, int] = {}

    cores = [normalise_name(n) for n in names]

    def candidates(role: str, side: str) -> list[int]:
        hits = []
        for j, (s, core) in enumerate(cores):
            if s == side and not words[j][2] and (rank := _pattern_rank(core, role)) is not None:
                hits.append((rank, j))
        return [j for _, j in sorted(hits)]

    def shallowest_below(root: int, pool: list[int]) -> int | None:
        below = [j for j in pool if j != root and tree.is_ancestor(root, j)]
        return min(below, key=lambda j: tree.depth[j]) if below else None

    def nearest_above(j: int, pool: list[int]) -> int | None:
        p = int(tree.parents[j])
        while p >= 0:
            if p in pool:
                return p
            p = int(tree.parents[p])
        return None

    def anchor(middle: str, top: str, side: str) -> tuple[int | None, int | None]:
        middles, tops = candidates(middle, side), candidates(top, side)
        mid = next(
            (k for k in middles if any(t != k and tree.is_ancestor(t, k) for t in tops)),
            middles[0] if middles else None,
        )
        if mid is None:
            return None, None
        upper = nearest_above(mid, tops)
        if upper is None:
            upper = int(tree.parents[mid])
            while upper >= 0 and words[upper][2]:
                upper = int(tree.parents[upper])
        return (upper if upper >= 0 else None), mid

    for side in ("L", "R"):
        thigh, knee = anchor("LowerLeg", "UpperLeg", side)
        if knee is not None:
            out[f"LowerLeg_{side}"] = knee
            if thigh is not None:
                out[f"UpperLeg_{side}"] = thigh
            foot = shallowest_below(knee, candidates("Foot", side))
            if foot is not None:
                out[f"Foot_{side}"] = foot
                toe = shallowest_below(foot, candidates("Toes", side))
                if toe is not None:
                    out[f"Toes_{side}"] = toe
        upper, elbow = anchor("LowerArm", "UpperArm", side)
        if elbow is not None:
            out[f"LowerArm_{side}"] = elbow
            if upper is not None:
                out[f"UpperArm_{side}"] = upper
                clav = nearest_above(upper, [c for c in candidates("Shoulder", side) if c != upper])
                if clav is not None:
                    out[f"Shoulder_{side}"] = clav
            hand = shallowest_below(elbow, candidates("Hand", side))
            if hand is not None:
                out[f"Hand_{side}"] = hand
    heads = [j for j, (s, roles, _) in enumerate(words) if not s and "Head" in roles]
    if heads:
        out["Head"] = min(heads, key=lambda h: tree.depth[h])
    return out


# --------------------------------------------------------------------------- the hierarchy


class _Tree:
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


def _complete_trunk(
    tree: _Tree,
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
    tree: _Tree,
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
    skeleton: Skeleton, m: dict[str, int], tree: _Tree | None = None
) -> str | None:
    """What is wrong with a mapping's order in the hierarchy (a knee above its thigh, an
    arm not below the hips, one joint in two roles), or None."""
    tree = tree or _Tree(skeleton)
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


# --------------------------------------------------------------------------- geometry


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


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _facing(
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


def _side_votes(
    poses: np.ndarray, up: np.ndarray, fwd: np.ndarray, a: int, b: int
) -> tuple[float, float]:
    """How clearly joint ``a`` sits on the body's left of ``b`` (+1) or right (-1), and the
    strength of the facing cue it rests on (mean forward vector length, in leg lengths)."""
    strength = np.linalg.norm(fwd, axis=-1)
    left = _unit(np.cross(up, fwd))
    d = _unit(poses[:, a] - poses[:, b])
    vote = np.sum(d * left, axis=-1)
    w = strength
    if w.sum() < 1e-9:
        return 0.0, 0.0
    return float(np.sum(w * vote) / w.sum()), float(strength.mean())


def _body_up(poses: np.ndarray, hips: int, chest: int) -> np.ndarray:
    return _unit(poses[:, chest] - poses[:, hips])


# --------------------------------------------------------------------------- structure


def _major_tips(tree: _Tree, helper: np.ndarray, keep: int) -> tuple[list[int], np.ndarray]:
    """Leaves of the long chains: the shortest side branches (measured from the junction
    they leave, helpers counted short) are pruned until ``keep`` leaves remain. Returns
    the leaves and, per joint, how many branches were pruned from it."""
    alive = np.ones(tree.n, dtype=bool)
    alive_children = np.array([len(c) for c in tree.children])
    pruned = np.zeros(tree.n, dtype=int)
    while True:
        leaves = np.nonzero(alive & (alive_children == 0))[0]
        if len(leaves) <= keep:
            break
        pendants = []
        for leaf in leaves:
            length, k, named_helper = tree.end[leaf], int(leaf), False
            while True:
                named_helper |= bool(helper[k])
                p = int(tree.parents[k])
                if p < 0 or alive_children[p] != 1:
                    break
                length += tree.bone[k]
                k = p
            if p < 0:
                continue  # the one chain left down from the root
            length += tree.bone[k]
            pendants.append((length * (0.01 if named_helper else 1.0), int(leaf), k))
        if not pendants:
            break
        pendants.sort()
        for _, leaf, top in pendants[: max(1, (len(leaves) - keep) // 2)]:
            j = leaf
            while True:
                alive[j] = False
                if j == top:
                    break
                j = int(tree.parents[j])
            p = int(tree.parents[top])
            alive_children[p] -= 1
            pruned[p] += 1
    return [int(j) for j in np.nonzero(alive & (alive_children == 0))[0]], pruned


@dataclass
class _Chain:
    joints: list[int]  # from the junction's child down to the tip
    reach: np.ndarray  # (len,) length along the bones from the junction to each joint
    total: float  # to the tip's End Site
    kink: np.ndarray  # (len,) mean bend in degrees at each joint over the sampled poses


def _chain(tree: _Tree, poses: np.ndarray, ends: np.ndarray, top: int, tip: int) -> _Chain:
    """The chain from below ``top`` to ``tip`` in ``poses (N, J, 3)``; ``ends (N, J, 3)``
    places each joint's End Site (the tip's bone ends there)."""
    joints = tree.path(top, tip)
    reach = np.cumsum(tree.bone[joints])
    total = float(reach[-1] + tree.end[tip]) if joints else 0.0
    kink = np.zeros(len(joints))
    # bend at a joint: between the bone arriving and the bone leaving, skipping joints that
    # sit on their parent (zero-length bones)
    points = [poses[:, j] for j in [top, *joints]]
    lengths = [0.0, *tree.bone[joints]]
    if tree.end[tip] > tree.tiny:
        points.append(ends[:, tip])
        lengths.append(tree.end[tip])
    for i in range(1, min(len(points) - 1, len(joints) + 1)):
        before = i - 1
        while before > 0 and lengths[before + 1] <= tree.tiny:
            before -= 1
        after = i + 1
        while after < len(points) - 1 and lengths[after] <= tree.tiny:
            after += 1
        if lengths[i] <= tree.tiny or lengths[after] <= tree.tiny:
            continue
        u, v = points[i] - points[before], points[after] - points[i]
        cos = np.sum(_unit(u) * _unit(v), axis=-1)
        kink[i - 1] = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())
    return _Chain(joints, reach, total, kink)


_LIMB_SHAPE = {  # upper to lower bone length: the range real rigs span; the part before
    # the limb (pelvis, clavicle) and after it (foot, hand) as a fraction of the limb
    "leg": ((0.75, 1.3), 0.25, 0.40),
    "arm": ((0.9, 1.6), 0.45, 0.55),
}


def _limb_joints(
    chain: _Chain,
    tree: _Tree,
    kind: str,
    words: list[tuple[str, set[str], bool]],
    pruned: np.ndarray,
) -> tuple[tuple[int, int, int], float, float]:
    """The chain's (upper, middle, end) joints (hip, knee, ankle or shoulder, elbow, wrist)
    as chain positions, the cost of that reading and its margin over the next best that
    puts the joints elsewhere."""
    (low, high), before_max, after_max = _LIMB_SHAPE[kind]
    roles = ("UpperLeg", "LowerLeg", "Foot") if kind == "leg" else ("UpperArm", "LowerArm", "Hand")
    js, s = chain.joints, chain.reach
    n = len(js)
    scored = []
    for a, b, c in itertools.combinations(range(n), 3):
        upper, lower = s[b] - s[a], s[c] - s[b]
        if upper <= tree.tiny or lower <= tree.tiny:
            continue
        ratio = upper / lower
        cost = (np.log(max(low / ratio, ratio / high, 1.0)) / 0.35) ** 2
        limb = upper + lower
        cost += 3.0 * max(0.0, s[a] / limb - before_max)
        cost += 1.5 * max(0.0, (chain.total - s[c]) / limb - after_max)  # a prop may go on
        # joints between hip and knee, knee and ankle, that bend are joints of their own
        cost += sum(chain.kink[i] for i in range(a + 1, c) if i != b) / 15.0
        cost += 3.0 * sum(not tree.rotates[js[i]] for i in (a, b, c))
        if kind == "leg" and chain.total > s[c] + tree.tiny:
            cost += 0.5 * max(0.0, 1.0 - chain.kink[c] / 45.0)  # the foot turns at the ankle
        if kind == "arm":  # the hand is where fingers branch
            hand = [c] + [i for i in range(c + 1, n) if s[i] - s[c] <= tree.tiny]
            branches = sum(len(tree.children[js[i]]) - (i + 1 < n) for i in hand)
            cost -= 0.2 * min(branches, 3)
        for i, role in zip((a, b, c), roles, strict=True):
            if role in words[js[i]][1]:
                cost -= 0.7
            if words[js[i]][2]:
                cost += 0.7
        cost += 1e-3 * (a + b + c)  # of joints on one spot, the upper one
        scored.append((float(cost), (a, b, c)))
    if not scored:
        raise MotionError("chain too short for a limb", kind="unusable")
    scored.sort()
    cost, best = scored[0]
    where = s[list(best)]
    margin = next(
        (c2 - cost for c2, other in scored[1:] if np.abs(s[list(other)] - where).max() > tree.tiny),
        10.0,
    )
    return best, cost, margin


def _head_joint(chain: _Chain, tree: _Tree, pruned: np.ndarray, words) -> int:
    """Position in the head chain of the head: where face bones branch, a joint named
    head, else the last joint that rotates."""
    js = chain.joints
    named = [i for i, j in enumerate(js) if "Head" in words[j][1]]
    if named:
        return named[0]
    branching = [i for i, j in enumerate(js) if i > 0 and pruned[j]]
    if branching:
        return branching[0]
    rotating = [i for i, j in enumerate(js) if tree.rotates[j] and not words[j][2]]
    return rotating[-1] if rotating else len(js) - 1


@dataclass
class _Reading:
    """One assignment of five chain tips to legs, arms and head."""

    cost: float
    hips: int
    chest: int
    legs: tuple[int, int]
    arms: tuple[int, int]
    head: int


def _readings(
    tree: _Tree,
    poses: np.ndarray,
    tips: list[int],
    words,
    helper: np.ndarray,
    limb: Callable[[str, int, int], tuple[_Chain, tuple[int, int, int], float, float]],
) -> list[_Reading]:
    """Every topologically possible assignment of five of ``tips`` to legs, arms and head,
    best first. ``limb(kind, top, tip)`` reads a chain as a leg or arm (its joints and cost)."""
    out = []
    length_to = {}

    def along(top: int, tip: int) -> float:
        key = (top, tip)
        if key not in length_to:
            length_to[key] = float(tree.bone[tree.path(top, tip)].sum() + tree.end[tip])
        return length_to[key]

    def family_fit(top: int, tip: int, family: set[str]) -> float:
        js = tree.path(top, tip)
        fit = [1.0 if words[j][1] & family else -1.0 for j in js if words[j][1]]
        return float(np.mean(fit)) if fit else 0.0

    def limb_length(kind: str, top: int, tip: int) -> tuple[float, float]:
        chain, (a, _, c), cost, _ = limb(kind, top, tip)
        return float(chain.reach[c] - chain.reach[a]), cost

    leg_words, arm_words = set(LEG_ROLES), set(ARM_ROLES)
    for five in itertools.combinations(tips, 5):
        hips = tree.lca(*five)
        for legs in itertools.combinations(five, 2):
            rest = [t for t in five if t not in legs]
            for head in rest:
                arms = tuple(t for t in rest if t != head)
                upper = tree.lca(*arms, head)
                if upper == hips or not tree.is_ancestor(hips, upper):
                    continue
                if any(tree.is_ancestor(upper, leg) for leg in legs):
                    continue
                ll = [along(hips, t) for t in legs]
                la = [along(upper, t) for t in arms]
                lh = along(upper, head)
                if min(ll + la + [lh]) <= tree.tiny:
                    continue
                try:
                    leg_limbs = [limb_length("leg", hips, t) for t in legs]
                    arm_limbs = [limb_length("arm", upper, t) for t in arms]
                except MotionError:
                    continue  # a chain too short to be a limb
                up = _body_up(poses, hips, upper)
                cost = 0.0
                for leg in legs:
                    d = _unit(poses[:, leg] - poses[:, hips])
                    cost += 2.0 * float(np.maximum(np.sum(d * up, axis=-1) + 0.5, 0.0).mean())
                d = _unit(poses[:, head] - poses[:, upper])
                cost += float(np.maximum(0.5 - np.sum(d * up, axis=-1), 0.0).mean())
                # pairs alike (hip to ankle, shoulder to wrist), each limb read well
                for pair in (leg_limbs, arm_limbs):
                    cost += 2.0 * abs(np.log(pair[0][0] / pair[1][0]))
                    cost += 0.5 * (pair[0][1] + pair[1][1])
                cost += 2.0 * max(0.0, np.log(lh / np.mean(la)) + 0.4)  # a head is short
                # each pair parts where it leaves the body, not further out (two fingers)
                cost += 5.0 * max(0.0, along(hips, tree.lca(*legs)) / min(ll) - 0.2)
                cost += 5.0 * max(0.0, along(upper, tree.lca(*arms)) / min(la) - 0.3)
                cost -= 0.5 * sum(family_fit(hips, t, leg_words) for t in legs)
                cost -= 0.5 * sum(family_fit(upper, t, arm_words) for t in arms)
                cost += 0.5 * sum(helper[t] for t in five)
                out.append(_Reading(float(cost), hips, upper, legs, arms, head))
    out.sort(key=lambda r: r.cost)
    return out


def by_structure(
    skeleton: Skeleton,
    motion: Motion | None = None,
    given: dict[str, int] | None = None,
    frames: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[dict[str, int], float]:
    """Map a humanoid from its hierarchy, bone lengths and geometry (names as evidence).

    Returns the mapping and a confidence in [0, 1]. Raises ``MotionError`` (unusable) when
    the skeleton does not read as a humanoid and :class:`AmbiguousRigError` when nothing
    tells its left from its right; ``given`` (canonical -> index) settles sides and roles
    it names.
    """
    given = given or {}
    names = skeleton.names
    if skeleton.num_joints > MAX_STRUCTURE_JOINTS:
        raise MotionError(
            f"{skeleton.num_joints} joints are too many to map by structure "
            f"(at most {MAX_STRUCTURE_JOINTS}); pass a 'mapping' of joint names",
            kind="unusable",
        )
    tree = _Tree(skeleton)
    words = _word_roles(names)
    helper = np.array([w[2] for w in words])
    if frames is None:
        frames = sample_frames(skeleton, motion)
    poses = sample_poses(skeleton, frames)
    ends = sample_ends(skeleton, frames)
    tips, pruned = _major_tips(tree, helper, keep=6)
    if len(tips) < 5:
        raise MotionError(
            f"the skeleton has {len(tips)} long chains; a humanoid has five "
            "(two legs, two arms, neck and head)",
            kind="unusable",
        )
    limbs_read: dict[tuple[str, int, int], tuple] = {}

    def read_limb(
        kind: str, top: int, tip: int
    ) -> tuple[_Chain, tuple[int, int, int], float, float]:
        key = (kind, top, tip)
        if key not in limbs_read:
            chain = _chain(tree, poses, ends, top, tip)
            try:
                limbs_read[key] = (chain, *_limb_joints(chain, tree, kind, words, pruned))
            except MotionError as e:
                limbs_read[key] = e
        found = limbs_read[key]
        if isinstance(found, MotionError):
            raise found
        return found

    readings = _readings(tree, poses, tips, words, helper, read_limb)
    if not readings:
        raise MotionError(
            "no two legs below a chest with two arms and a head in this hierarchy",
            kind="unusable",
        )
    best = readings[0]
    others = [r for r in readings[1:] if {r.head, *r.legs} != {best.head, *best.legs}]
    role_margin = others[0].cost - best.cost if others else 10.0
    m: dict[str, int] = {"Hips": best.hips, "Chest": best.chest}
    limb_margins = []
    limbs: dict[int, dict[str, int]] = {}
    for kind, tips2, top in (("leg", best.legs, best.hips), ("arm", best.arms, best.chest)):
        for tip in tips2:
            chain, (a, b, c), _, margin = read_limb(kind, top, tip)
            limb_margins.append(margin)
            js = chain.joints
            if kind == "leg":
                limb = {"UpperLeg": js[a], "LowerLeg": js[b], "Foot": js[c]}
                toes = [i for i in range(c + 1, len(js)) if tree.bone[js[i]] > tree.tiny]
                if toes and tree.rotates[js[toes[0]]]:
                    limb["Toes"] = js[toes[0]]
                limb["tip"] = js[-1] if len(js) - 1 > c else js[c]
            else:
                limb = {"UpperArm": js[a], "LowerArm": js[b], "Hand": js[c]}
                if a > 0 and tree.rotates[js[a - 1]]:
                    limb["Shoulder"] = js[a - 1]
            limbs[tip] = limb
    head_chain = _chain(tree, poses, ends, best.chest, best.head)
    m["Head"] = head_chain.joints[_head_joint(head_chain, tree, pruned, words)]
    pairs = {"legs": tuple(best.legs), "arms": tuple(best.arms)}
    decided, side_conf = _sides(poses, ends, best, limbs, pairs, given, words, tree)
    if len(decided) < 2:
        raise _ambiguous(skeleton, tree, pairs, limbs, [p for p in pairs if p not in decided])
    for pair, (t0, t1) in pairs.items():
        left, right = (t0, t1) if decided[pair] > 0 else (t1, t0)
        for side, tip in (("L", left), ("R", right)):
            for role, j in limbs[tip].items():
                if role != "tip":
                    m[f"{role}_{side}"] = j
    conf_roles = 1.0 - np.exp(-max(role_margin, 0.0) / 0.5)
    conf_limbs = 1.0 - np.exp(-max(min(limb_margins), 0.0) / 0.3)
    confidence = float(min(conf_roles, conf_limbs, *side_conf.values()))
    return m, round(max(0.0, min(1.0, confidence)), 3)


def _sides(
    poses: np.ndarray,
    ends: np.ndarray,
    best: _Reading,
    limbs: dict[int, dict[str, int]],
    pairs: dict[str, tuple[int, int]],
    given: dict[str, int],
    words,
    tree: _Tree,
) -> tuple[dict[str, float], dict[str, float]]:
    """Per pair of limbs (keyed "legs", "arms"), +1 if its first chain is the left one,
    -1 if the second, and how sure: the caller's mapping, else the facing (toes, knees)
    with names where the geometry is silent; a pair nothing decides follows the other's
    left. Pairs left undecided are missing from the result."""
    up = _body_up(poses, best.hips, best.chest)
    fwd = _facing(poses, ends, [limbs[t] for t in best.legs], up)
    root_of = {"legs": "UpperLeg", "arms": "UpperArm"}
    decided: dict[str, float] = {}
    conf: dict[str, float] = {}
    for pair, (t0, t1) in pairs.items():
        vote, strength = _side_votes(
            poses, up, fwd, limbs[t0][root_of[pair]], limbs[t1][root_of[pair]]
        )
        named = _given_side(given, limbs[t0], limbs[t1]) or _name_side(words, tree, limbs, t0, t1)
        if named:
            decided[pair] = named
            conf[pair] = 1.0 if vote * named > 0.3 and strength > 0.05 else 0.75
        elif abs(vote) >= 0.3 and strength >= 0.03:
            decided[pair] = float(np.sign(vote))
            conf[pair] = min(1.0, abs(vote) / 0.6) * min(1.0, strength / 0.15)
    for pair, other in (("legs", "arms"), ("arms", "legs")):
        if pair not in decided and other in decided:
            o0, o1 = pairs[other]
            key = root_of[other]
            lateral = (poses[:, limbs[o0][key]] - poses[:, limbs[o1][key]]) * decided[other]
            t0, t1 = pairs[pair]
            d = poses[:, limbs[t0][root_of[pair]]] - poses[:, limbs[t1][root_of[pair]]]
            vote = float(np.mean(np.sum(_unit(d) * _unit(lateral), axis=-1)))
            if abs(vote) >= 0.3:
                decided[pair] = float(np.sign(vote))
                conf[pair] = conf[other] * min(1.0, abs(vote) / 0.6)
    return decided, conf


def _given_side(given: dict[str, int], limb0: dict[str, int], limb1: dict[str, int]) -> float:
    """+1 if the caller's mapping puts ``limb0`` on the left, -1 on the right, 0 if silent."""
    for key, j in given.items():
        if key[-2:] in ("_L", "_R"):
            for sign, limb in ((1.0, limb0), (-1.0, limb1)):
                if j in limb.values():
                    return sign if key.endswith("_L") else -sign
    return 0.0


def _name_side(words, tree: _Tree, limbs, t0: int, t1: int) -> float:
    """+1 if names put chain ``t0`` on the left and ``t1`` on the right, -1 the other way."""

    def side(tip: int) -> str:
        top = min(limbs[tip].values(), key=lambda j: tree.depth[j])
        found = {words[j][0] for j in tree.path(int(tree.parents[top]), tip) if words[j][0]}
        return found.pop() if len(found) == 1 else ""

    s0, s1 = side(t0), side(t1)
    if {s0, s1} == {"L", "R"}:
        return 1.0 if s0 == "L" else -1.0
    return 0.0


def _ambiguous(skeleton, tree, pairs, limbs, undecided) -> AmbiguousRigError:
    names = skeleton.names
    what = {"legs": ("UpperLeg", "legs"), "arms": ("UpperArm", "arms")}
    chains = []
    example = {}
    for pair in undecided:
        role, label = what[pair]
        t0, t1 = pairs[pair]
        chains.append(
            {
                "limbs": label,
                "chains": [
                    [names[j] for j in tree.path(int(tree.parents[limbs[t][role]]), t)]
                    for t in (t0, t1)
                ],
            }
        )
        example[f"{role}_L"] = names[limbs[t0][role]]
    first = chains[0]
    message = (
        f"cannot tell left from right: the {first['limbs']} starting at "
        f"{first['chains'][0][0]!r} and {first['chains'][1][0]!r} are alike and nothing "
        "(toes, bent knees, names) shows which way the body faces; pass a 'mapping' that "
        f"names one side, e.g. {example}"
    )
    return AmbiguousRigError(message, chains=chains, example_mapping=example)


# --------------------------------------------------------------------------- both


def _explicit(skeleton: Skeleton, explicit: dict[str, str] | None) -> dict[str, int]:
    names = skeleton.names
    out: dict[str, int] = {}
    for a, b in (explicit or {}).items():
        if a in C.INDEX and b in names:
            out[a] = names.index(b)
        elif b in C.INDEX and a in names:
            out[b] = names.index(a)
        else:
            raise MotionError(
                f"mapping entry {a!r}: {b!r} names no canonical joint and joint of this file",
                kind="unusable",
            )
    return out


def _merge(auto: dict[str, int], given: dict[str, int]) -> dict[str, int]:
    out = dict(given)
    for k, v in auto.items():
        if k not in out and v not in out.values():
            out[k] = v
    return out


def by_names(
    skeleton: Skeleton, frames: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[dict[str, int], str]:
    """Canonical joint -> index from joint names alone (a convention's table, else word
    patterns; the trunk from the hierarchy), and the convention's name."""
    names = skeleton.names
    if names == C.JOINTS:
        return {n: i for i, n in enumerate(names)}, "Bandai (canonical)"
    tree = _Tree(skeleton)
    convention, table = match_convention(names)
    limbs = [f"{r}_{s}" for r in ("UpperLeg", "LowerLeg", "Foot", "UpperArm", "LowerArm", "Hand")
             for s in ("L", "R")] + ["Head"]  # fmt: skip
    found = table
    if not set(limbs) <= set(table):
        found = _merge(_pattern_limbs(tree, names), table)
        if len(table) < len(found) // 2:
            convention = ""
    if convention.startswith("MotionBuilder") and any(
        n.lower().startswith("mixamorig") for n in names
    ):
        convention = "Mixamo"
    return _complete_trunk(tree, names, found, frames), convention or "word patterns"


def names_confidence(m: dict[str, int], poses: np.ndarray, ends: np.ndarray) -> float:
    """How well a name mapping fits the rig's geometry (``poses`` and their End Sites
    ``ends``, :func:`sample_poses`, :func:`sample_ends`): legs hang from the hips, and the
    joints named left sit on the body's left given its facing (1 when both hold clearly,
    lower where the geometry is silent, near 0 where it disagrees)."""
    up = _body_up(poses, m["Hips"], m["Chest"])
    legs = []
    for s in ("L", "R"):
        leg = {r: m[f"{r}_{s}"] for r in ("UpperLeg", "LowerLeg", "Foot")}
        if f"Toes_{s}" in m:
            leg["tip"] = m[f"Toes_{s}"]
        legs.append(leg)
    down = min(
        float(np.mean(np.sum(_unit(poses[:, m[f"Foot_{s}"]] - poses[:, m["Hips"]]) * up, -1)))
        for s in ("L", "R")
    )
    fwd = _facing(poses, ends, legs, up)
    vote_legs, strength = _side_votes(poses, up, fwd, m["UpperLeg_L"], m["UpperLeg_R"])
    vote_arms, _ = _side_votes(poses, up, fwd, m["UpperArm_L"], m["UpperArm_R"])
    conf = 1.0
    if down > -0.5:
        conf = min(conf, 0.6)
    if strength < 0.03:
        return min(conf, 0.8)
    vote = min(vote_legs, vote_arms)
    if vote < 0:
        return min(conf, 0.3)
    return round(min(conf, 0.8 + 0.2 * min(1.0, vote / 0.6)), 3)


def find_mapping(
    skeleton: Skeleton,
    motion: Motion | None = None,
    explicit: dict[str, str] | None = None,
    frames: tuple[np.ndarray, np.ndarray] | None = None,
) -> RigMapping:
    """Canonical joint name -> index of the skeleton's joint that plays it.

    ``explicit`` maps joint names either way (``{"mixamorig:Hips": "Hips"}`` or
    ``{"Hips": "mixamorig:Hips"}``); its entries override the automatic ones. Names are
    tried first; where they do not name every required joint in a consistent hierarchy,
    the structure decides (``motion`` adds the clip's poses to the rest pose's geometry).
    Raises ``MotionError`` (kind ``"unusable"``, ``unmapped`` listing what names could not
    find) when neither works, :class:`AmbiguousRigError` when left and right cannot be told.
    ``frames`` (world rotations and positions of some of the clip's frames) saves computing
    them again (:func:`sample_frames`).
    """
    given = _explicit(skeleton, explicit)
    if frames is None:
        frames = sample_frames(skeleton, motion)
    tree = _Tree(skeleton)
    named, convention = by_names(skeleton, frames)
    m = _complete_trunk(tree, skeleton.names, _merge(named, given), frames)
    missing = [j for j in REQUIRED if j not in m]
    problem = None if missing else hierarchy_problem(skeleton, m, tree)
    if not missing and problem is None:
        if set(given) >= set(REQUIRED):
            return RigMapping(m, "given", 1.0, "")
        confidence = names_confidence(
            m, sample_poses(skeleton, frames), sample_ends(skeleton, frames)
        )
        return RigMapping(m, "names", confidence, convention)
    try:
        auto, confidence = by_structure(skeleton, motion, given, frames)
    except AmbiguousRigError:
        raise
    except MotionError as e:
        reason = f"no joint found for {', '.join(missing)}" if missing else problem or "no mapping"
        raise MotionError(
            f"cannot map the skeleton onto the canonical humanoid: by names, {reason}; "
            f"by structure, {e.message} (pass a 'mapping' of joint names)",
            kind="unusable",
            unmapped=missing or None,
        ) from None
    m = _complete_trunk(tree, skeleton.names, _merge(auto, given), frames)
    missing = [j for j in REQUIRED if j not in m]
    problem = f"no joint left for {', '.join(missing)}" if missing else None
    problem = problem or hierarchy_problem(skeleton, m, tree)
    if problem is not None:
        raise MotionError(
            f"cannot map the skeleton onto the canonical humanoid: {problem} "
            "(pass a 'mapping' of joint names)",
            kind="unusable",
        )
    return RigMapping(m, "structure", confidence, "")

"""Joint names as evidence: the naming conventions' tables and the word patterns.

A table per naming convention (:data:`CONVENTIONS`) is matched case-insensitively after any
common prefix (a namespace such as ``mixamorig:``, a skeleton name such as ``Skeleton1_``):
the convention that names the most joints wins (:func:`match_convention`). Where no table
names the limbs, generic word patterns do (``thigh``, ``upleg``, ``forearm``,
``clavicle``..., sides from ``L``/``Left``/``.L``/``_l``; :func:`word_roles`), after
:func:`normalise_name` strips rig decorations.
"""

from __future__ import annotations

import functools
import re

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
def pattern_rank(core: str, role: str) -> int | None:
    """Index of the first of ``role``'s patterns the core matches ("leg" must not match
    "upleg"; trailing digits are allowed: toe0, neck01), or None."""
    for rank, pattern in enumerate(_LIMB_PATTERNS[role]):
        if re.fullmatch(pattern + r"\d*", core):
            return rank
    return None


def word_roles(names: tuple[str, ...]) -> list[tuple[str, set[str], bool]]:
    """Per joint: its name's side, the limb roles its words fit, and whether it is a helper."""
    out = []
    for n in names:
        side, core = normalise_name(n)
        helper = any(w in core for w in _HELPER_WORDS)
        roles = set()
        if not helper:
            roles = {r for r in _LIMB_PATTERNS if pattern_rank(core, r) is not None}
            if re.fullmatch(r"(head|skull)\d*", core):
                roles.add("Head")
        out.append((side, roles, helper))
    return out

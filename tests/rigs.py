"""Exporter-style variants of real clips, made by code for tests.

Each variant performs exactly the same motion in world space (same joint
positions) but presents it the way another tool would: other joint names
(Mixamo, Unreal, 3ds Max Biped, Blender), rotated joint frames (Maya/Bandai
style, rest pose meaningless), an A-pose rest, an extra root above the hips,
other channel orders and channel counts.

The rig corpus (:func:`corpus`) goes further, for the mapper that reads rigs by
structure: every skeleton layout of ``../shared/data`` (or, without it, the CMU
fixture) renamed to numbers and to random words, with its children shuffled,
helper, twist and prop bones inserted, turned Z-up, scaled by 0.01 and 100, in an
A-pose, on a root bone on the floor, and all of that at once; and rigs of other
tools' conventions rebuilt from the fixture (:func:`rebuild`): Reallusion CC/iClone,
Maya ``_JNT``, MB-Lab, Kinect v2, Xsens MVN, Second Life, VRoid, Daz Genesis 8 and 9,
OptiTrack Motive, Vicon Plug-in Gait.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import kinematics as K
from motion import rotations as rot
from motion.rig_names import normalise_name
from motion.skeleton import Motion, Skeleton
from tests.convention_rigs import CONVENTION_RIGS

# the variants are part of this module's face (tests call rigs.renamed, rigs.z_up, ...)
from training.rig_variants import (  # noqa: F401
    CMU_TO_BIPED,
    CMU_TO_BLENDER,
    CMU_TO_MIXAMO,
    CMU_TO_UNREAL,
    a_pose,
    random_frames,
    reframed,
    renamed,
    scaled,
    variants,
    with_animated_translations,
    with_channels,
    with_extra_root,
    z_up,
)

FIXTURE = Path(__file__).parent / "data" / "cmu_02_01_walk_30fps.bvh"


def load_fixture() -> Motion:
    return bvh.load(FIXTURE)


# --------------------------------------------------------------------------- rig corpus


@dataclass(frozen=True)
class CorpusRig:
    """A corpus rig: its clip, the clip it was made from, which of its joints is which joint
    of the source (``origin``: name -> source name, for joints that copy one), and the
    mapping method it should be found by."""

    motion: Motion
    source: Motion
    origin: dict[str, str]
    method: str


# One clip per skeleton layout of the shared data (Xia shares CMU's layout, not its actor).
SHARED_LAYOUTS = {
    "cmu31": ("cmu-31", "02_01.bvh"),
    "xia": ("xia", "angry_13_000.bvh"),
    "daz43": ("cmu-dance-43", "05_20.bvh"),
    "max31": ("cmu-dance-3dsmax", "94_01_indian_dance.bvh"),
    "bandai": ("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh"),
}
TPOSE_LAYOUTS = ("fixture", "cmu31", "xia", "daz43")  # Y-up T-pose rests an A-pose can bend


def cut(motion: Motion, frames: int = 48, fps: float = 30.0) -> Motion:
    """At most ``frames`` frames at about ``fps`` (every n-th frame), to keep tests quick."""
    step = max(1, round(motion.fps / fps))
    out = motion.slice(0, frames * step)
    return out.replace(lrot=out.lrot[::step], lpos=out.lpos[::step], fps=motion.fps / step)


def _with_names(motion: Motion, names: tuple[str, ...]) -> Motion:
    sk = motion.skeleton
    return motion.replace(
        skeleton=Skeleton(names, sk.parents, sk.offsets, sk.channels, sk.end_sites)
    )


def renamed_numbers(motion: Motion, seed: int = 0) -> Motion:
    """Every joint named by a number, in no particular order (``j017``)."""
    perm = np.random.default_rng(seed).permutation(motion.skeleton.num_joints)
    return _with_names(motion, tuple(f"j{p:03d}" for p in perm))


_SYLLABLES = [c + v for c in "bdfgkmnpstvz" for v in "aeiou"]


def random_words(count: int, seed: int = 0) -> tuple[str, ...]:
    """``count`` distinct made-up words that name no body part, side or helper."""
    from motion.rig_names import word_roles

    rng = np.random.default_rng(seed)
    out: list[str] = []
    while len(out) < count:
        word = "".join(rng.choice(_SYLLABLES, size=int(rng.integers(2, 4))))
        word = word.capitalize() if rng.random() < 0.5 else word
        side, roles, helper = word_roles((word,))[0]
        if word not in out and not (side or roles or helper or normalise_name(word)[0]):
            out.append(word)
    return tuple(out)


def renamed_words(motion: Motion, seed: int = 0) -> Motion:
    """Every joint named by a made-up word."""
    return _with_names(motion, random_words(motion.skeleton.num_joints, seed))


def reordered(motion: Motion, order: list[int]) -> Motion:
    """The same rig with its joints listed in ``order`` (parents first): BVH children
    follow the list, so this changes the order of children in the file."""
    sk = motion.skeleton
    new_index = {old: new for new, old in enumerate(order)}
    parents = np.array([-1 if sk.parents[j] < 0 else new_index[int(sk.parents[j])] for j in order])
    new_sk = Skeleton(
        tuple(sk.names[j] for j in order),
        parents,
        sk.offsets[order],
        tuple(sk.channels[j] for j in order),
        {new_index[j]: v for j, v in sk.end_sites.items()},
    )
    return Motion(new_sk, motion.fps, motion.lrot[:, order], motion.lpos[:, order])


def shuffled_children(motion: Motion, seed: int = 0) -> Motion:
    """Every joint's children in a random order."""
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    order: list[int] = []

    def visit(j: int) -> None:
        order.append(j)
        for c in rng.permutation(sk.children(j)):
            visit(int(c))

    visit(0)
    return reordered(motion, order)


# A rebuilt joint: name, parent name (None for the root) and where it is in the world,
# from the source clip's world rotations (F, J, 4) and positions (F, J, 3) and times (F,).
Place = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def copy_of(j: int) -> Place:
    """The source joint ``j`` itself."""
    return lambda grot, gpos, t: (grot[:, j], gpos[:, j])


def fixed_to(j: int, offset, turn=(0.0, 0.0, 0.0)) -> Place:
    """Rigidly attached to source joint ``j``: at ``offset`` in its frame, turned by the
    rotation vector ``turn``."""
    offset, q = np.asarray(offset, dtype=float), rot.from_rotvec(np.asarray(turn, dtype=float))
    return lambda grot, gpos, t: (
        rot.mul(grot[:, j], q),
        gpos[:, j] + rot.apply(grot[:, j], offset),
    )


def twisting(j: int, child_offset, fraction: float = 0.5, degrees: float = 25.0) -> Place:
    """A twist bone between source joint ``j`` and its child at ``child_offset`` (in ``j``'s
    frame): ``fraction`` of the way along, turning about the bone by up to ``degrees``."""
    axis = np.asarray(child_offset, dtype=float)
    axis = axis / np.linalg.norm(axis)

    def place(grot, gpos, t):
        q = rot.from_rotvec(np.radians(degrees) * np.sin(2.0 * t)[:, None] * axis)
        return rot.mul(grot[:, j], q), gpos[:, j] + rot.apply(
            grot[:, j], fraction * np.asarray(child_offset)
        )

    return place


def on_floor_below(j: int, up: int = 1) -> Place:
    """Unrotated, on the floor below source joint ``j`` (root motion of game rigs)."""

    def place(grot, gpos, t):
        pos = gpos[:, j].copy()
        pos[:, up] = 0.0
        return rot.identity((len(t),)), pos

    return place


def rebuild(
    motion: Motion, joints: list[tuple[str, str | None, Place]], order: str = "ZXY"
) -> Motion:
    """A new rig performing ``motion``: each joint placed in the world by its ``Place``,
    parents listed first. Joints whose place relative to their parent varies get position
    channels; the OFFSET is the first frame's, so the rest pose is the source's where the
    joints copy it."""
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    t = np.arange(motion.num_frames) / motion.fps
    names = [n for n, _, _ in joints]
    parents = np.array([-1 if p is None else names.index(p) for _, p, _ in joints])
    world = [place(grot, gpos, t) for _, _, place in joints]
    wrot = np.stack([w[0] for w in world], axis=1)
    wpos = np.stack([w[1] for w in world], axis=1)
    prot = np.where((parents >= 0)[None, :, None], wrot[:, np.maximum(parents, 0)], rot.IDENTITY)
    ppos = np.where((parents >= 0)[None, :, None], wpos[:, np.maximum(parents, 0)], 0.0)
    lrot = rot.mul(rot.inv(prot), wrot)
    lpos = rot.apply(rot.inv(prot), wpos - ppos)
    moves = np.ptp(lpos, axis=0).max(axis=-1) > 1e-6 * max(np.ptp(wpos), 1e-9)
    rot_ch = tuple(f"{a}rotation" for a in order)
    pos_ch = ("Xposition", "Yposition", "Zposition")
    channels = tuple(
        pos_ch + rot_ch if (p < 0 or mv) else rot_ch for p, mv in zip(parents, moves, strict=True)
    )
    leaves = [j for j in range(len(names)) if j not in parents]
    end_sites = {j: ((0.0, 0.0, 0.0),) for j in leaves}
    src = {n: i for i, n in enumerate(motion.skeleton.names)}
    for j, (name, _, _) in enumerate(joints):
        if name in src and src[name] in motion.skeleton.end_sites:
            end_sites[j] = motion.skeleton.end_sites[src[name]]
    sk = Skeleton(tuple(names), parents, lpos[0], channels, end_sites)
    return Motion(sk, motion.fps, rot.make_continuous(lrot), lpos)


def source_mapping(motion: Motion) -> dict[str, int]:
    """Canonical joint -> index in ``motion`` found by names (the corpus' ground truth)."""
    return retarget.make_rig(motion.skeleton, motion).mapping


def with_helpers(motion: Motion, seed: int = 0) -> Motion:
    """Twist bones inside the upper arms, forearms, thighs and shins (turning about the
    bone), twist leaves on them, and a long prop in the right hand: the mapped joints keep
    their world motion."""
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    m = source_mapping(motion)
    by_index = {v: k for k, v in m.items()}
    pairs = {}
    for s in ("L", "R"):
        for a, b in (("UpperArm", "LowerArm"), ("LowerArm", "Hand"), ("UpperLeg", "LowerLeg"),
                     ("LowerLeg", "Foot")):  # fmt: skip
            if sk.parents[m[f"{b}_{s}"]] == m[f"{a}_{s}"]:
                pairs[m[f"{b}_{s}"]] = m[f"{a}_{s}"]
    height = retarget.make_rig(sk, motion).height
    joints: list[tuple[str, str | None, Place]] = []
    for j, name in enumerate(sk.names):
        parent = None if sk.parents[j] < 0 else sk.names[sk.parents[j]]
        if j in pairs:
            a = pairs[j]
            helper = f"{name}_in"
            frac = float(rng.uniform(0.3, 0.7))
            joints.append(
                (helper, parent, twisting(a, sk.offsets[j], frac, float(rng.uniform(10, 40))))
            )
            parent = helper
        joints.append((name, parent, copy_of(j)))
        role = by_index.get(j, "")
        if role.startswith(("UpperArm", "LowerArm", "UpperLeg", "LowerLeg")):
            joints.append((f"{name}_leaf", name, fixed_to(j, np.zeros(3), (0.0, 0.0, 0.3))))
        if role == "Hand_R":
            along = sk.offsets[m["Hand_R"]] / np.linalg.norm(sk.offsets[m["Hand_R"]])
            joints.append((f"{name}_prop", name, fixed_to(j, 0.35 * height * along)))
    return rebuild(motion, joints)


def root_on_floor(motion: Motion, moving: bool = False) -> Motion:
    """A new root bone on the floor below the old root (at the origin, or following the
    hips on the floor with ``moving``): in the rest pose the hips stand a bone above it."""
    sk = motion.skeleton
    hips = source_mapping(motion)["Hips"]
    root: Place = (
        on_floor_below(hips)
        if moving
        else (lambda grot, gpos, t: (rot.identity((len(t),)), np.zeros((len(t), 3))))
    )
    joints: list[tuple[str, str | None, Place]] = [("floor_root", None, root)]
    for j, name in enumerate(sk.names):
        parent = "floor_root" if sk.parents[j] < 0 else sk.names[sk.parents[j]]
        joints.append((name, parent, copy_of(j)))
    return rebuild(motion, joints)


def bind_pose_first(motion: Motion) -> Motion:
    """``motion`` with its first frame in the rig's bind pose (every joint at its rest
    rotation, the root where it was), as a capture that opens on its bind pose."""
    lrot = motion.lrot.copy()
    lrot[0] = [0.0, 0.0, 0.0, 1.0]
    return motion.replace(lrot=lrot)


def a_pose_by_mapping(motion: Motion) -> Motion:
    """Rest pose with the upper arms 45 degrees down (world motion unchanged), found by
    the rig's mapping rather than names."""
    sk = motion.skeleton
    m = source_mapping(motion)
    frames = rot.identity((sk.num_joints,))
    for s, sign in (("L", 1.0), ("R", -1.0)):
        frames[m[f"UpperArm_{s}"]] = rot.from_rotvec(np.array([0.0, 0.0, sign * np.pi / 4]))
    return reframed(motion, frames)


def _name_origin(variant: Motion, source: Motion) -> dict[str, str]:
    return dict(zip(variant.skeleton.names, source.skeleton.names, strict=True))


def layout_variants(name: str, motion: Motion) -> dict[str, CorpusRig]:
    """The corpus' variants of one clip."""
    out: dict[str, CorpusRig] = {}

    def add(key: str, m: Motion, origin: dict[str, str], method: str = "structure") -> None:
        out[f"{name}/{key}"] = CorpusRig(m, motion, origin, method)

    same = {n: n for n in motion.skeleton.names}
    numbers = renamed_numbers(motion, 1)
    add("numbers", numbers, _name_origin(numbers, motion))
    words = renamed_words(motion, 2)
    add("words", words, _name_origin(words, motion))
    shuffled = shuffled_children(numbers, 3)
    add(
        "numbers_shuffled",
        shuffled,
        {n: _name_origin(numbers, motion)[n] for n in shuffled.skeleton.names},
    )
    helpers = with_helpers(motion, 4)
    add("helpers", helpers, {n: n for n in helpers.skeleton.names if n in same}, "names")
    helpers_words = renamed_words(helpers, 5)
    origin = {
        w: n
        for w, n in zip(helpers_words.skeleton.names, helpers.skeleton.names, strict=True)
        if n in same
    }
    add("helpers_words", helpers_words, origin)
    add("z_up_numbers", z_up(numbers), _name_origin(numbers, motion))
    add("scaled_0.01_numbers", scaled(numbers, 0.01), _name_origin(numbers, motion))
    add("scaled_100_words", scaled(words, 100.0), _name_origin(words, motion))
    floor = root_on_floor(motion)
    floor_numbers = renamed_numbers(floor, 6)
    add("root_on_floor_numbers", floor_numbers,
        {a: b for a, b in zip(floor_numbers.skeleton.names, floor.skeleton.names, strict=True) if b in same})  # fmt: skip
    moving = renamed_words(root_on_floor(motion, moving=True), 7)
    add("root_motion_words", moving,
        {a: b for a, b in zip(moving.skeleton.names, floor.skeleton.names, strict=True) if b in same})  # fmt: skip
    if name in TPOSE_LAYOUTS:
        apose = renamed_numbers(a_pose_by_mapping(motion), 8)
        add("a_pose_numbers", apose, _name_origin(apose, motion))
    frames = renamed_numbers(random_frames(motion, 9), 10)
    add("rotated_frames_numbers", frames, _name_origin(frames, motion))
    # a performance of its own (its translations move the joints): its source is itself
    # under the source's names
    animated = with_animated_translations(motion)
    animated_numbers = renamed_numbers(animated, 14)
    out[f"{name}/animated_translations_numbers"] = CorpusRig(
        animated_numbers, animated, _name_origin(animated_numbers, animated), "structure"
    )
    everything = scaled(
        z_up(shuffled_children(renamed_words(with_helpers(motion, 11), 12), 13)), 0.01
    )
    helpers11 = with_helpers(motion, 11)
    words11 = renamed_words(helpers11, 12)
    origin = {
        w: n
        for w, n in zip(words11.skeleton.names, helpers11.skeleton.names, strict=True)
        if n in same
    }
    add("everything", everything, origin)
    return out


def frozen(motion: Motion, names: tuple[str, ...]) -> Motion:
    """The clip with these joints held at their rest rotation (their children take over
    their world rotation), so that a rig without them can copy the rest."""
    sk = motion.skeleton
    lrot = motion.lrot.copy()
    for name in names:
        j = sk.names.index(name)
        for c in sk.children(j):
            lrot[:, c] = rot.mul(lrot[:, j], lrot[:, c])
        lrot[:, j] = rot.IDENTITY
    return motion.replace(lrot=lrot)


_SIDES = {
    "L": {"{L}": "L", "{l}": "l", "{Left}": "Left"},
    "R": {"{L}": "R", "{l}": "r", "{Left}": "Right"},
}


def _sided(text, side: str):
    if isinstance(text, tuple):
        return tuple(_sided(t, side) for t in text)
    if not isinstance(text, str):
        return text
    for token, value in _SIDES[side].items():
        text = text.replace(token, value)
    return text


def convention_rig(source: Motion, convention: str) -> CorpusRig:
    """The fixture rebuilt as a rig of ``convention`` (:data:`CONVENTION_RIGS`)."""
    freeze, rows = CONVENTION_RIGS[convention]
    src = frozen(source, freeze)
    sk = src.skeleton
    idx = {n: i for i, n in enumerate(sk.names)}
    joints: list[tuple[str, str | None, Place]] = []
    origin: dict[str, str] = {}
    seen = set()
    for row in rows:
        sides = ("L", "R") if any(t in repr(row) for t in ("{L}", "{l}", "{Left}")) else ("L",)
        for side in sides:
            name, parent, how = (_sided(x, side) for x in row)
            if name in seen:
                continue
            seen.add(name)
            if isinstance(how, str):
                place, origin[name] = copy_of(idx[how]), how
            elif how[0] == "floor":
                place = lambda grot, gpos, t: (rot.identity((len(t),)), np.zeros((len(t), 3)))  # noqa: E731
            else:
                a, b, f = idx[how[1]], idx[how[2]], how[3]
                off = sk.offsets[b] if b != a else _tip_offset(sk, a)
                place = fixed_to(a, f * off) if how[0] == "at" else twisting(a, off, f)
            joints.append((name, parent, place))
    return CorpusRig(rebuild(src, joints), src, origin, "names")


def _tip_offset(sk: Skeleton, j: int) -> np.ndarray:
    """A step beyond joint ``j`` in its frame, continuing the bone that reaches it (fingers
    on a hand, toes on a toe base; the fixture's joint frames are the world's at rest)."""
    return 0.25 * sk.offsets[j]


def corpus(sources: dict[str, Motion]) -> dict[str, CorpusRig]:
    """The rig corpus: every layout variant of every source clip, and the conventions rebuilt
    from the CMU fixture (under key ``"fixture"``, or the first source)."""
    out: dict[str, CorpusRig] = {}
    for name, motion in sources.items():
        out.update(layout_variants(name, motion))
    base = sources.get("fixture", next(iter(sources.values())))
    for convention in CONVENTION_RIGS:
        out[f"convention/{convention}"] = convention_rig(base, convention)
    return out


def walk_cycle(motion: Motion | None = None, rig_names: dict[str, str] | None = None) -> Motion:
    """A closed walk loop as a game export writes one (its last frame repeats its first,
    the root's travel aside): one gait cycle of the CMU walk fixture, cut at the frame
    pair one cycle apart whose poses match best, the remaining mismatch of every joint's
    rotation and of the root's height spread over the cycle (the root's travel on the
    floor kept), on the fixture's rig (renamed by ``rig_names``, e.g. CMU_TO_MIXAMO)."""
    motion = motion or load_fixture()
    gpos = K.global_positions(motion)
    about_root = gpos - gpos[:, :1] * np.array([1.0, 0.0, 1.0])
    best = None
    for a in range(5, motion.num_frames - 45):
        gaps = np.linalg.norm(about_root[a + 25 : a + 45] - about_root[a], axis=-1).mean(axis=-1)
        b = a + 25 + int(np.argmin(gaps))
        if best is None or gaps.min() < best[0]:
            best = (float(gaps.min()), a, b)
    _, a, b = best
    cut = motion.slice(a, b + 1)
    n = cut.num_frames - 1
    weight = (np.arange(n + 1) / n)[:, None]
    residual = rot.mul(rot.inv(cut.lrot[-1]), cut.lrot[0])  # last * r = first
    spread = rot.slerp(rot.identity(residual.shape[:-1])[None].repeat(n + 1, 0),
                       residual[None].repeat(n + 1, 0), weight)  # fmt: skip
    lrot = rot.mul(cut.lrot, spread)
    lpos = cut.lpos.copy()
    lpos[:, 0, 1] += weight[:, 0] * (cut.lpos[0, 0, 1] - cut.lpos[-1, 0, 1])
    looped = cut.replace(lrot=lrot, lpos=lpos)
    return renamed(looped, rig_names) if rig_names else looped

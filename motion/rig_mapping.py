"""Which joint of a skeleton plays which canonical joint: :func:`find_mapping`.

The steps: a ``mapping`` the caller gives; then names (:func:`by_names`: a convention's
table or word patterns from :mod:`motion.rig_names`, the trunk from the hierarchy,
:mod:`motion.rig_tree`); where they do not name every required joint in a consistent
hierarchy, the structure (:func:`motion.rig_structure.by_structure`). Names are checked
against the rig's own geometry (:func:`names_confidence`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion import canonical as C
from motion.errors import AmbiguousRigError, MotionError
from motion.rig_names import match_convention, normalise_name, pattern_rank, word_roles
from motion.rig_structure import by_structure
from motion.rig_tree import (
    JointTree,
    body_up,
    complete_trunk,
    facing,
    hierarchy_problem,
    normalised,
    sample_ends,
    sample_frames,
    sample_poses,
    side_votes,
)
from motion.skeleton import Motion, Skeleton

REQUIRED = (
    "Hips", "Chest", "Head",
    "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R", "LowerArm_R", "Hand_R",
    "UpperLeg_L", "LowerLeg_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R",
)  # fmt: skip


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


def _pattern_limbs(tree: JointTree, names: tuple[str, ...]) -> dict[str, int]:
    """Limbs and head by word patterns, each limb anchored on its knee (elbow)."""
    words = word_roles(names)
    out: dict[str, int] = {}

    cores = [normalise_name(n) for n in names]

    def candidates(role: str, side: str) -> list[int]:
        hits = []
        for j, (s, core) in enumerate(cores):
            if s == side and not words[j][2] and (rank := pattern_rank(core, role)) is not None:
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
    tree = JointTree(skeleton)
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
    return complete_trunk(tree, names, found, frames), convention or "word patterns"


def names_confidence(m: dict[str, int], poses: np.ndarray, ends: np.ndarray) -> float:
    """How well a name mapping fits the rig's geometry (``poses`` and their End Sites
    ``ends``, :func:`sample_poses`, :func:`sample_ends`): legs hang from the hips, and the
    joints named left sit on the body's left given its facing (1 when both hold clearly,
    lower where the geometry is silent, near 0 where it disagrees)."""
    up = body_up(poses, m["Hips"], m["Chest"])
    legs = []
    for s in ("L", "R"):
        leg = {r: m[f"{r}_{s}"] for r in ("UpperLeg", "LowerLeg", "Foot")}
        if f"Toes_{s}" in m:
            leg["tip"] = m[f"Toes_{s}"]
        legs.append(leg)
    down = min(
        float(np.mean(np.sum(normalised(poses[:, m[f"Foot_{s}"]] - poses[:, m["Hips"]]) * up, -1)))
        for s in ("L", "R")
    )
    fwd = facing(poses, ends, legs, up)
    vote_legs, strength = side_votes(poses, up, fwd, m["UpperLeg_L"], m["UpperLeg_R"])
    vote_arms, _ = side_votes(poses, up, fwd, m["UpperArm_L"], m["UpperArm_R"])
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
    tree = JointTree(skeleton)
    named, convention = by_names(skeleton, frames)
    m = complete_trunk(tree, skeleton.names, _merge(named, given), frames)
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
    m = complete_trunk(tree, skeleton.names, _merge(auto, given), frames)
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

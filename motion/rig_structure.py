"""A humanoid read from its structure where its names do not say which joint is which.

Short side branches (fingers, toes, twist and helper leaves, eyes, props) are pruned until a
few long chains remain; the assignment of five of them to legs, arms and head that fits a
humanoid best wins: the legs' junction below the other three's, legs hanging down from the
hips and the head up from the chest in the rest pose and the clip's frames, pairs of
similar length. Within each limb the knee (elbow) is the split of the chain into two bones
of similar length whose in-between joints do not bend; the hand is where fingers branch.
Left and right come from the facing, measured on the feet (toes point forward) and the
knees (they bend forward), then from name sides. Names weigh in as evidence throughout. A
rig whose sides nothing tells apart is refused with
:class:`~motion.errors.AmbiguousRigError`, which says how to pass a ``mapping``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from motion.errors import AmbiguousRigError, MotionError
from motion.rig_names import word_roles
from motion.rig_tree import (
    JointTree,
    body_up,
    facing,
    normalised,
    sample_ends,
    sample_frames,
    sample_poses,
    side_votes,
)
from motion.skeleton import Motion, Skeleton

LEG_ROLES = ("UpperLeg", "LowerLeg", "Foot", "Toes")


ARM_ROLES = ("Shoulder", "UpperArm", "LowerArm", "Hand")


MAX_STRUCTURE_JOINTS = 2000  # pruning is quadratic at worst; real rigs have a few hundred


def _major_tips(tree: JointTree, helper: np.ndarray, keep: int) -> tuple[list[int], np.ndarray]:
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


def _chain(tree: JointTree, poses: np.ndarray, ends: np.ndarray, top: int, tip: int) -> _Chain:
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
        cos = np.sum(normalised(u) * normalised(v), axis=-1)
        kink[i - 1] = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean())
    return _Chain(joints, reach, total, kink)


_LIMB_SHAPE = {  # upper to lower bone length: the range real rigs span; the part before
    # the limb (pelvis, clavicle) and after it (foot, hand) as a fraction of the limb
    "leg": ((0.75, 1.3), 0.25, 0.40),
    "arm": ((0.9, 1.6), 0.45, 0.55),
}


def _limb_joints(
    chain: _Chain,
    tree: JointTree,
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


def _head_joint(chain: _Chain, tree: JointTree, pruned: np.ndarray, words) -> int:
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
    tree: JointTree,
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
                up = body_up(poses, hips, upper)
                cost = 0.0
                for leg in legs:
                    d = normalised(poses[:, leg] - poses[:, hips])
                    cost += 2.0 * float(np.maximum(np.sum(d * up, axis=-1) + 0.5, 0.0).mean())
                d = normalised(poses[:, head] - poses[:, upper])
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
    tree = JointTree(skeleton)
    words = word_roles(names)
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
    tree: JointTree,
) -> tuple[dict[str, float], dict[str, float]]:
    """Per pair of limbs (keyed "legs", "arms"), +1 if its first chain is the left one,
    -1 if the second, and how sure: the caller's mapping, else the facing (toes, knees)
    with names where the geometry is silent; a pair nothing decides follows the other's
    left. Pairs left undecided are missing from the result."""
    up = body_up(poses, best.hips, best.chest)
    fwd = facing(poses, ends, [limbs[t] for t in best.legs], up)
    root_of = {"legs": "UpperLeg", "arms": "UpperArm"}
    decided: dict[str, float] = {}
    conf: dict[str, float] = {}
    for pair, (t0, t1) in pairs.items():
        vote, strength = side_votes(
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
            vote = float(np.mean(np.sum(normalised(d) * normalised(lateral), axis=-1)))
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


def _name_side(words, tree: JointTree, limbs, t0: int, t1: int) -> float:
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

"""The dance's feet: contacts predicted from the generated motion, the feet planted there.

The dance network's feet hover a few centimetres over the floor and glide with the body;
its own contact channels stay near zero (they regress to the mean of a 13% share). A
ballroom dancer always stands on at least one foot, so :func:`predict_contacts` picks a
supporting foot every frame (the slower one, with hysteresis and a shortest stance), adds
the other foot where it too is still, and splits each stance into heel and toe by which
is lower. :func:`travel_on_support` carries the body across the floor over its planted
feet (the network dances in place), and :func:`plant_feet` then stands it on the floor
there (the hips moved up or down), holds each contact still by leg IK, and lifts every
foot in the air clear of the floor. The figures that chose it: docs/dance_alignment.md (Feet).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion import canonical as C
from motion import contacts as CT
from motion import grounding
from motion import kinematics as K
from motion.ik import leg_joints, move_ankles, pin_feet
from motion.skeleton import Motion

LEG = C.leg_length()
FEET = list(CT.CANONICAL_FOOT_JOINTS)  # Foot_L, Toes_L, Foot_R, Toes_R
SPEED_SMOOTH = 1.0  # Gaussian sigma (frames) of the feet's speeds
SWITCH_RATIO = 1.3  # the support passes to the other foot when it is this much slower
MIN_STANCE_SECONDS = 0.15
STILL_SPEED = 0.15  # leg lengths per second: the free foot counts as planted under it
HEEL_TOE_MARGIN = 0.03  # leg lengths: a heel (toe) this much higher than the toe (heel) is up
GROUND_WINDOW_SECONDS = 2.0
STILL_HEIGHT = 0.08  # leg lengths over the local ground: the free foot, planted, under it
GROUND_SECONDS = 0.3  # Gaussian sigma of the hips' move onto the floor
CLEARANCE = 0.05  # leg lengths: feet in the air lifted at least this far over the floor
BLEND_SECONDS = 0.1  # pin_feet's ramps, replaced over a swing by spread_over_swings
OPEN_SWING_SECONDS = 1 / 3  # before the first contact and after the last: the arc's rise
LIFT_SMOOTH = 1.5  # Gaussian sigma (frames) of the lift, across the contacts' edges too
TRAVEL_PASSES = 3  # contacts predicted, the body carried over them: twice more on the result
TRAVEL_SMOOTH = 4.0  # Gaussian sigma (frames) of the body's steps over its planted feet


def _speeds(gpos: np.ndarray, fps: float) -> np.ndarray:
    """Each foot's speed on the floor ``(F, 2)``: the slower of heel and toe, smoothed."""
    v = CT.horizontal_speed(gpos[:, FEET], fps)
    v = np.minimum(v[:, 0::2], v[:, 1::2])
    return gaussian_filter1d(v, SPEED_SMOOTH, axis=0, mode="nearest")


def _forward_fill(state: np.ndarray) -> np.ndarray:
    """``state (F,)`` float with NaN where undecided: each NaN takes the last decided value."""
    known = ~np.isnan(state)
    if not known.any():
        return np.zeros(len(state), dtype=np.int64)
    index = np.where(known, np.arange(len(state)), 0)
    np.maximum.accumulate(index, out=index)
    first = int(np.argmax(known))
    out = state[index]
    out[:first] = state[first]
    return out.astype(np.int64)


def support_foot(speed: np.ndarray, fps: float) -> np.ndarray:
    """``(F,)`` 0 (left) or 1 (right): the foot the dancer stands on. The slower foot, the
    support passing over only when the other is :data:`SWITCH_RATIO` slower; a stance
    shorter than :data:`MIN_STANCE_SECONDS` goes to the foot before it."""
    ratio = np.log((speed[:, 0] + 1e-3) / (speed[:, 1] + 1e-3))
    margin = np.log(SWITCH_RATIO)
    state = np.where(ratio < -margin, 0.0, np.where(ratio > margin, 1.0, np.nan))
    support = _forward_fill(state)
    shortest = max(1, int(round(MIN_STANCE_SECONDS * fps)))
    for _ in range(3):  # a merged stance can make another one short: a few passes
        change = np.flatnonzero(np.diff(support)) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [len(support)]])
        short = (stops - starts < shortest) & (starts > 0)
        if not short.any():
            break
        for a, b in zip(starts[short], stops[short], strict=True):
            support[a:b] = support[a - 1]
    return support


def predict_contacts(gpos: np.ndarray, fps: float, network: np.ndarray | None = None) -> np.ndarray:
    """Contacts ``(F, 4)`` bool of Foot_L, Toes_L, Foot_R, Toes_R of a generated dance from
    its global positions ``gpos (F, 22, 3)`` (the feet's at least): the supporting foot
    (:func:`support_foot`) always, the other one where it is still (under
    :data:`STILL_SPEED`) and low (within :data:`STILL_HEIGHT` of the local ground) or where
    the network's own contacts ``network (F, 4)`` have its heel or toe down; of a foot in
    contact, the heel and the toe unless one is :data:`HEEL_TOE_MARGIN` higher than the
    other over their ground levels."""
    gpos = np.asarray(gpos, dtype=np.float64)
    frames = len(gpos)
    if frames == 0:
        return np.zeros((0, 4), dtype=bool)
    speed = _speeds(gpos, fps)
    support = support_foot(speed, fps)
    heights = gpos[:, FEET, 1]
    ground = CT.local_ground(heights, fps, GROUND_WINDOW_SECONDS)
    low = np.minimum(heights[:, 0::2], heights[:, 1::2]) - ground[:, None] < STILL_HEIGHT * LEG
    still = (speed < STILL_SPEED * LEG) & low
    shortest = max(1, int(round(MIN_STANCE_SECONDS * fps)))
    if network is not None:  # the network's own contacts, of heel or toe
        still |= np.asarray(network, dtype=bool).reshape(frames, 2, 2).any(axis=2)
    still = CT.clean_contacts(still, shortest)
    stance = np.stack([support == 0, support == 1], axis=1) | still
    over = heights - CT.ground_heights(gpos, FEET, LEG)[None]
    heel, toe = over[:, 0::2], over[:, 1::2]
    contacts = np.zeros((frames, 4), dtype=bool)
    contacts[:, 0::2] = stance & (heel <= toe + HEEL_TOE_MARGIN * LEG)
    contacts[:, 1::2] = stance & (toe <= heel + HEEL_TOE_MARGIN * LEG)
    return contacts


def floor_levels(gpos: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """Each foot joint's height on the floor ``(4,)``: the median of its heights in its
    contacts (where the network stands it, so the hips move up as often as down), its
    ground level when it has none. A low percentile instead lowered whole dances by 6 cm
    (18 cm for one), bending their knees."""
    out = CT.ground_heights(gpos, FEET, LEG)
    for i, j in enumerate(FEET):
        if contacts[:, i].any():
            out[i] = np.median(gpos[contacts[:, i], j, 1])
    return out


def travel_on_support(motion: Motion, contacts: np.ndarray) -> Motion:
    """``motion`` with its hips carried across the floor by its planted feet: each frame the
    body moves by minus the mean floor displacement of the feet in contact at that frame and
    the next (``contacts (F, 4)``), smoothed over :data:`TRAVEL_SMOOTH` frames, so a foot on
    the floor stays put and the body travels over it. The network learnt its dances in
    place (its training dances had lost their path across the floor), so where a real
    dancer's body passes over the standing foot, its standing foot slides back under the
    hips instead."""
    contacts = np.asarray(contacts, dtype=bool)
    gpos = CT.canonical_foot_positions(motion)[:, FEET][..., [0, 2]]
    frames = motion.num_frames
    if frames < 2:
        return motion
    point = 0.5 * (gpos[:, 0::2] + gpos[:, 1::2])  # (F, 2 feet, 2): between heel and toe
    planted = contacts[:, 0::2] | contacts[:, 1::2]
    both = (planted[1:] & planted[:-1]).astype(np.float64)  # (F - 1, 2)
    step = np.diff(point, axis=0)  # (F - 1, 2, 2)
    weight = both.sum(axis=1, keepdims=True)
    slide = (step * both[..., None]).sum(axis=1) / np.maximum(weight, 1.0)
    slide = gaussian_filter1d(slide, TRAVEL_SMOOTH, axis=0, mode="nearest")
    path = np.zeros((frames, 3))
    path[1:, [0, 2]] = -np.cumsum(slide, axis=0)
    lpos = motion.lpos.copy()
    lpos[:, C.INDEX["Hips"]] += path
    return motion.replace(lpos=lpos)


def plant_feet(motion: Motion, contacts: np.ndarray) -> Motion:
    """A canonical dance stood on its floor where ``contacts (F, 4)`` say (the hips moved
    up or down, Gaussian :data:`GROUND_SECONDS`), each contact held still by leg IK (flat
    feet in one orientation), and every foot in the air lifted :data:`CLEARANCE` over its
    ground level."""
    contacts = np.asarray(contacts, dtype=bool)
    if not contacts.any():
        return motion
    legs = grounding.CANONICAL_LEGS
    parents = motion.skeleton.parents
    _, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=leg_joints(legs))
    levels = dict(zip(FEET, floor_levels(gpos, contacts).tolist(), strict=True))
    grounded = grounding.ground_hips(motion, contacts, levels, C.INDEX["Hips"], GROUND_SECONDS)
    blend = max(1, int(round(BLEND_SECONDS * motion.fps)))
    pinned = pin_feet(
        grounded, contacts[:, [0, 2]], legs, blend_frames=blend,
        toe_contacts=contacts[:, [1, 3]], hold_flat_feet=True, levels=levels,
    )  # fmt: skip
    pinned = spread_over_swings(grounded, pinned, contacts)
    return lift_free_feet(pinned, levels, contacts)


def spread_over_swings(before: Motion, pinned: Motion, contacts: np.ndarray) -> Motion:
    """``pinned`` (``before`` with its contacts held by :func:`pin_feet`) with each foot's
    move between two contacts spread over the whole swing: the ankle's displacement from
    ``before`` goes from where the last contact left it to where the next one wants it
    smoothly (smoothstep over the swing), instead of ramping out and in over a few frames
    next to each contact, which jerked the knees."""
    legs = grounding.CANONICAL_LEGS
    parents = pinned.skeleton.parents
    joints = leg_joints(legs)
    _, g0 = K.fk(before.lrot, before.lpos, parents, joints=joints)
    grot, gpos = K.fk(pinned.lrot, pinned.lpos, parents, joints=joints)
    lrot = pinned.lrot.copy()
    frames = pinned.num_frames
    t = np.arange(frames)
    extra = []
    for i, (_, _, ankle, _) in enumerate(legs):
        planted = contacts[:, 2 * i] | contacts[:, 2 * i + 1]
        have = gpos[:, ankle] - g0[:, ankle]
        where = np.flatnonzero(planted)
        want = have.copy()
        if where.size:
            nxt = np.minimum(np.searchsorted(where, t), where.size - 1)
            prv = np.maximum(np.searchsorted(where, t, side="right") - 1, 0)
            a, b = where[prv], where[nxt]
            inside = (a < t) & (t < b)  # a swing between two contacts
            u = np.where(inside, (t - a) / np.maximum(b - a, 1), 0.0)
            u = u * u * (3.0 - 2.0 * u)
            between = (1.0 - u)[:, None] * have[a] + u[:, None] * have[b]
            want = np.where(inside[:, None], between, have)
        extra.append(np.where(planted[:, None], 0.0, want - have))
    move_ankles(lrot, grot, gpos, parents, legs, extra)
    return pinned.replace(lrot=lrot)


def swing_arc(planted: np.ndarray, fps: float) -> np.ndarray:
    """``(F,)`` 0 where ``planted``, between two contacts ``sin(pi u)`` of the swing's phase
    ``u`` (0 at the lift-off, 1 at the touch-down), and rising from 0 to 1 over
    :data:`OPEN_SWING_SECONDS` before the first contact and after the last (1 everywhere
    when there is none)."""
    frames = len(planted)
    where = np.flatnonzero(planted)
    if where.size == 0:
        return np.ones(frames)
    t = np.arange(frames)
    last = where[np.maximum(np.searchsorted(where, t, side="right") - 1, 0)]
    nxt = where[np.minimum(np.searchsorted(where, t), where.size - 1)]
    u = np.clip((t - last) / np.maximum(nxt - last, 1), 0.0, 1.0)
    arc = np.sin(np.pi * u)
    rise = max(1.0, OPEN_SWING_SECONDS * fps)
    arc = np.where(t < where[0], np.clip((where[0] - t) / rise, 0.0, 1.0), arc)
    arc = np.where(t > where[-1], np.clip((t - where[-1]) / rise, 0.0, 1.0), arc)
    return np.where(planted, 0.0, arc)


def lift_free_feet(motion: Motion, levels: dict[int, float], contacts: np.ndarray) -> Motion:
    """``motion`` with each foot out of contact lifted by leg IK until its lower point
    (heel or toe) is over its level in ``levels`` by :data:`CLEARANCE` times the swing's
    arc (:func:`swing_arc`): the foot leaves the floor and comes down onto it the way a
    step does. The lift is smoothed across the contacts' edges and not cut there, so a
    contact's first or last frames may stand the foot a little up (on the held-out dances
    at most 1.5 cm, 2 % of contact frames over 5 mm) rather than jump (a lift ramped in
    over 0.04 s and cut at each contact had made the legs' jerk 1.2 times real dances';
    docs/dance_alignment.md). The foot keeps its rotation."""
    legs = grounding.CANONICAL_LEGS
    parents = motion.skeleton.parents
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=leg_joints(legs))
    lrot = motion.lrot.copy()
    offsets = []
    for i, (_, _, ankle, toe) in enumerate(legs):
        planted = contacts[:, 2 * i] | contacts[:, 2 * i + 1]
        want = CLEARANCE * LEG * swing_arc(planted, motion.fps)
        low = np.minimum(gpos[:, ankle, 1] - levels[ankle], gpos[:, toe, 1] - levels[toe])
        lift = np.where(planted, 0.0, np.maximum(want - low, 0.0))
        offset = np.zeros((motion.num_frames, 3))
        offset[:, 1] = gaussian_filter1d(lift, LIFT_SMOOTH, mode="nearest")
        offsets.append(offset)
    move_ankles(lrot, grot, gpos, parents, legs, offsets)
    return motion.replace(lrot=lrot)


def clean_feet(motion: Motion, network: np.ndarray | None = None) -> Motion:
    """The dance's foot clean-up: :func:`predict_contacts` (with the network's contacts
    ``network (F, 4)`` bool, when given), the body carried over them
    (:func:`travel_on_support`), then :func:`plant_feet`."""
    moved = motion
    for _ in range(TRAVEL_PASSES):  # contacts read again on the travelling body: clearer
        contacts = predict_contacts(CT.canonical_foot_positions(moved), motion.fps, network)
        moved = travel_on_support(motion, contacts)
    return plant_feet(moved, contacts)

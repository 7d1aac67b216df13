"""Inverse kinematics: two-bone leg IK and feet pinned to their contacts (fitting rotations
to positions is :mod:`motion.fit`).

Quaternions are (x, y, z, w) as in :mod:`motion.rotations`; positions ``(F, J, 3)``,
Y up. Everything is vectorised over frames and loops over joints, legs or contact
segments only. Functions return new arrays and motions and leave their inputs alone.
The clean-up of a canonical motion's feet built on this is :mod:`motion.grounding`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from motion import contacts as CT
from motion import ik_kernels
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion

# Below this bend (sine of the knee's offset angle from the hip-ankle line, ~0.06
# degrees) the pole takes over from the current bend direction; above it an unmoved
# target leaves the leg exactly where it is.
POLE_WEIGHT = 1e-3
BLEND_SECONDS = 0.2  # default ramp in and out of a pinned contact
REACH_EPS = 1e-3  # pinned legs stretch to at most 1 - REACH_EPS of their length
SOFT_REACH = 0.05  # ...easing in over the last 5% of it


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)[..., None]  # np.sum over a short axis is slow


class LegSolution(NamedTuple):
    """Result of :func:`two_bone_ik`, all ``(..., 4)`` or ``(..., 3)``.

    ``hip_turn`` rotates the thigh (and everything below it) about the hip;
    ``knee_turn`` then rotates the shin about the moved knee. Both are world-frame
    rotations: new global rotation of the thigh = ``hip_turn * old``, of the shin =
    ``knee_turn * hip_turn * old``. ``knee`` and ``ankle`` are the new positions.
    """

    hip_turn: np.ndarray
    knee_turn: np.ndarray
    knee: np.ndarray
    ankle: np.ndarray


def two_bone_ik(
    hip: np.ndarray,
    knee: np.ndarray,
    ankle: np.ndarray,
    target: np.ndarray,
    pole: np.ndarray | None = None,
    eps: float = 1e-3,
) -> LegSolution:
    """Analytic two-bone IK moving ``ankle`` to ``target`` (all ``(..., 3)``, broadcasting).

    Bone lengths are kept. The knee stays on the side it is bent to now: its bend
    direction (perpendicular to the hip-ankle line) is carried along as that line turns
    towards the target, so the knee never flips. ``pole (..., 3)`` says which way a
    (nearly) straight leg bends, e.g. the knee's forward direction; without it a
    straight leg bends towards an arbitrary side. Targets out of reach straighten the
    leg to ``1 - eps`` of full extension (or leave it as straight as it already is);
    targets too close bend it to ``|thigh - shin| + eps * (thigh + shin)`` from the hip.
    """
    hinted = pole is not None
    arrays = np.broadcast_arrays(
        *(
            np.asarray(x, dtype=np.float64)
            for x in (hip, knee, ankle, target, pole if hinted else hip)
        )
    )
    shape = arrays[0].shape[:-1]
    flat = [np.ascontiguousarray(x.reshape(-1, 3)) for x in arrays]
    hip_turn, knee_turn, knee_new, ankle_new = ik_kernels.two_bone_ik(
        *flat, hinted, eps, POLE_WEIGHT
    )
    return LegSolution(
        hip_turn.reshape(shape + (4,)),
        knee_turn.reshape(shape + (4,)),
        knee_new.reshape(shape + (3,)),
        ankle_new.reshape(shape + (3,)),
    )


def leg_joints(legs: list[tuple[int, int, int, int | None]]) -> list[int]:
    return [j for leg in legs for j in leg if j is not None]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of True in a 1-D bool array."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, stops = np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist()
    return list(zip(starts, stops, strict=True))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _pin_offsets(
    ankle: np.ndarray,
    toe: np.ndarray | None,
    ankle_contact: np.ndarray,
    toe_contact: np.ndarray | None,
    ankle_ground: float,
    toe_ground: float,
    blend: int,
    hold_height: bool = True,
) -> np.ndarray:
    """Displacements ``(F, 3)`` to add to the ankle so each contact holds still.

    During a contact the anchor is held at one place: the segment's average on the
    floor, and the ground level vertically (with ``hold_height``; else only raised to
    it, never lowered). The anchor is the ankle, or the toe where
    only the toe touches; where both touch it rolls along the foot from heel to toe
    (the foot keeps its rotation, so one point of it can be held, not two). The
    displacement stays continuous as the anchor moves. Around the contacts it ramps
    in and out over ``blend`` frames.
    """
    if toe is None or toe_contact is None:
        toe, toe_contact = ankle, np.zeros(len(ankle), dtype=bool)
    return ik_kernels.pin_offsets(
        np.ascontiguousarray(ankle, dtype=np.float64),
        np.ascontiguousarray(toe, dtype=np.float64),
        np.ascontiguousarray(ankle_contact, dtype=bool),
        np.ascontiguousarray(toe_contact, dtype=bool),
        float(ankle_ground),
        float(toe_ground),
        int(blend),
        bool(hold_height),
    )


def _held_rotations(grot: np.ndarray, flat: np.ndarray, blend: int) -> np.ndarray:
    """Global foot rotations ``(F, 4)`` held at each flat contact's average (``flat (F,)``:
    heel and toe both down), eased in and out over ``blend`` frames around it.

    Every contact at once: the ramps fall with the distance to a contact, so each frame
    outside one follows the nearer of the contacts before and after it (the earlier on a
    tie), as if each contact had been laid over the frames in turn."""
    frames = len(grot)
    target, weight = grot.copy(), np.zeros(frames)
    runs = _runs(flat)
    if runs:
        starts, stops = (np.array(edge) for edge in zip(*runs, strict=True))
        inside = np.flatnonzero(flat)
        run_of = np.searchsorted(starts, inside, side="right") - 1
        run = grot[inside]
        first = grot[starts][run_of]
        run = np.where(np.sum(run * first, axis=-1, keepdims=True) < 0, -run, run)
        total = np.zeros((len(runs), 4))
        np.add.at(total, run_of, run)  # frame by frame, as run.sum(axis=0) adds them
        held = rot.normalize(total)
        t = np.arange(frames, dtype=np.float64)
        before = np.searchsorted(stops, t, side="right") - 1  # the contact that ended last
        after = np.searchsorted(starts, t, side="right")  # the next one to start
        w_before = _smoothstep(1.0 - (t - stops[np.maximum(before, 0)] + 1) / (blend + 1))
        w_after = _smoothstep(1.0 - (starts[np.minimum(after, len(runs) - 1)] - t) / (blend + 1))
        w_before[before < 0], w_after[after == len(runs)] = 0.0, 0.0
        which = np.where(w_after > w_before, after, before)
        weight = np.maximum(w_before, w_after)
        which[inside], weight[inside] = run_of, 1.0
        eased = weight > 0
        target[eased] = held[which[eased]]
    return rot.slerp(grot, target, weight)


def _chain(parents: np.ndarray, top: int, bottom: int) -> list[int]:
    """Joints from ``top`` down to the parent of ``bottom``, top first."""
    out = []
    j = int(parents[bottom])
    while j != top:
        if j < 0:
            raise MotionError(f"joint {bottom} is not below joint {top}", kind="unusable")
        out.append(j)
        j = int(parents[j])
    return [top] + out[::-1]


def _within_reach(hip, knee, ankle, target) -> np.ndarray:
    """Targets ``(F, 3)`` the leg can reach without snapping straight.

    Near full extension a small change of distance swings the knee a lot, so the leg's
    extension beyond its current one eases towards ``1 - REACH_EPS`` of its length over
    the last ``SOFT_REACH`` of it; the target then moves up (not sideways), so the foot
    lifts a little rather than slides. Targets no farther than the ankle is now stay.
    """
    full = rot.norm(knee - hip) + rot.norm(ankle - knee)
    now = rot.norm(ankle - hip)
    longest = np.minimum(full, np.maximum((1.0 - REACH_EPS) * full, now))
    rel = target - hip
    wanted = rot.norm(rel)
    knee_soft = np.minimum(np.maximum(longest - SOFT_REACH * full, now), longest)
    room = np.maximum(longest - knee_soft, 1e-12)
    eased = knee_soft + room * -np.expm1(-np.maximum(wanted - knee_soft, 0.0) / room)
    reach = np.where(wanted > knee_soft, np.minimum(eased, longest), wanted)
    floor_dist2 = rel[:, 0] ** 2 + rel[:, 2] ** 2
    lift = (wanted > reach) & (floor_dist2 < reach**2)
    drop = np.sqrt(np.maximum(reach**2 - floor_dist2, 0.0))
    out = target.copy()
    out[:, 1] = np.where(lift, hip[:, 1] + np.where(rel[:, 1] < 0, -drop, drop), target[:, 1])
    return out


def _knee_poles(grot_hip, hip, knee, ankle, toe, frames) -> np.ndarray:
    """Forward direction of each knee at ``frames`` ``(N, 3)``: the clip's average hinge
    axis in the thigh's frame, or failing that (a leg never bent) the foot's direction."""
    grot_hip, hip, knee, ankle = (np.ascontiguousarray(x, dtype=np.float64)
                                  for x in (grot_hip, hip, knee, ankle))  # fmt: skip
    frames = np.asarray(frames, dtype=np.int64)
    hinge_local, thigh, shin = ik_kernels.knee_hinge(grot_hip, hip, knee, ankle)
    if np.linalg.norm(hinge_local) > 1e-3 * (thigh * shin) * len(hip):
        hinge = hinge_local / np.linalg.norm(hinge_local)
        return ik_kernels.knee_poles(grot_hip, hip, ankle, ankle, frames, hinge, 0)
    if toe is not None:
        toe = np.ascontiguousarray(toe, dtype=np.float64)
        return ik_kernels.knee_poles(grot_hip, hip, ankle, toe, frames, np.zeros(3), 1)
    return np.zeros((len(frames), 3))


def pin_feet(
    motion: Motion,
    contacts: np.ndarray,
    legs: list[tuple[int, int, int, int | None]],
    blend_frames: int | None = None,
    toe_contacts: np.ndarray | None = None,
    hold_flat_feet: bool = False,
    levels: dict[int, float] | None = None,
    posed: tuple[np.ndarray, np.ndarray] | None = None,
    hold_height: bool = True,
) -> Motion:
    """Foot-contact clean-up: each foot held still during its contacts, by leg IK.

    ``contacts (F, n_feet)`` bool says when each foot's ankle touches the ground;
    ``legs`` gives each foot's ``(hip, knee, ankle, toe)`` joints (``toe`` may be
    None). ``toe_contacts (F, n_feet)`` optionally says when each toe touches: where
    only the toe does (heel off) the toe is held, and where both do the held point
    rolls from heel to toe. The held position is the contact's average on the floor
    and the ground level vertically (``levels``, joint -> height, where given, else
    :func:`contacts.ground_heights` of the motion itself); the correction
    ramps in and out over ``blend_frames`` (0.2 s by default). A leg that would have
    to stretch straight lifts the foot a little instead (see ``SOFT_REACH``).

    Hip and knee rotations change; the ankle keeps its global rotation, so the foot's
    orientation does not (so with heel and toe both down, one point of a rolling foot
    is held, not two); bone lengths are untouched and the knee keeps bending the way
    it bends. With ``hold_flat_feet`` (and toe contacts) a foot flat on the ground also
    keeps one orientation, its average over the contact: generated motion turns planted
    feet about, which slides whatever point of the foot is not the held one. Works on
    any skeleton given the joint indices. ``posed``: the legs' forward kinematics
    (:func:`kinematics.fk` with the legs' joints), when the caller has it; used up (its
    arrays change in place). Without ``hold_height`` a contact is held at its place on
    the floor and keeps its height unless that is under the ground level, for a caller
    that has put the feet on the floor already (:func:`ground_hips`).
    """
    contacts = np.asarray(contacts, dtype=bool)
    frames = motion.num_frames
    if contacts.shape != (frames, len(legs)):
        raise MotionError(f"contacts must be ({frames}, {len(legs)}), got {contacts.shape}")
    if toe_contacts is not None:
        toe_contacts = np.asarray(toe_contacts, dtype=bool)
        if toe_contacts.shape != contacts.shape:
            raise MotionError(f"toe contacts must be {contacts.shape}, got {toe_contacts.shape}")
    blend = int(round(BLEND_SECONDS * motion.fps)) if blend_frames is None else int(blend_frames)
    parents = motion.skeleton.parents
    if posed is None:
        grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=leg_joints(legs))
    else:
        grot, gpos = posed
    lrot = motion.lrot.copy()
    if hold_flat_feet and toe_contacts is not None:
        for i, (_, _, ankle, toe) in enumerate(legs):
            flat = contacts[:, i] & toe_contacts[:, i]
            if flat.any():
                held = _held_rotations(grot[:, ankle], flat, blend)
                local = rot.mul(rot.inv(grot[:, int(parents[ankle])]), held)
                lrot[:, ankle] = np.where(_dot(local, lrot[:, ankle]) < 0, -local, local)
                # only the foot moved: pose it again, not the whole leg
                foot = [ankle] if toe is None else _chain(parents, ankle, toe) + [toe]
                K.repose(grot, gpos, lrot, motion.lpos, parents, foot)

    ankles = [leg[2] for leg in legs]
    toes = [leg[3] for leg in legs if leg[3] is not None]
    if levels is None:
        leg_len = np.mean([CT.chain_length(motion.skeleton, leg[0], leg[2]) for leg in legs])
        found = CT.ground_heights(gpos, ankles + toes, leg_len)
        levels = dict(zip(ankles + toes, found, strict=True))

    offsets = []
    for i, (_, _, ankle, toe) in enumerate(legs):
        toe_c = None if toe_contacts is None or toe is None else toe_contacts[:, i]
        offsets.append(
            _pin_offsets(
                gpos[:, ankle],
                None if toe is None else gpos[:, toe],
                contacts[:, i],
                toe_c,
                levels[ankle],
                levels[toe] if toe is not None else levels[ankle],
                blend,
                hold_height,
            )
        )
    move_ankles(lrot, grot, gpos, parents, legs, offsets)
    return motion.replace(lrot=lrot)


def move_ankles(
    lrot: np.ndarray,
    grot: np.ndarray,
    gpos: np.ndarray,
    parents: np.ndarray,
    legs: list[tuple[int, int, int, int | None]],
    offsets: list[np.ndarray],
) -> None:
    """Moves each leg's ankle by its ``offsets (F, 3)`` where they are not zero, by leg
    IK, in ``lrot`` (in place; ``grot``/``gpos`` its forward kinematics before). Hip and
    knee turn; the ankle keeps its global rotation; the knee bends the way it bends.

    Every leg's moved frames go through one IK solve, laid end to end (the IK is per
    frame): on a short clip the cost is numpy's per-call overhead, paid once, not per leg."""
    moved = [np.nonzero(np.any(o != 0.0, axis=-1))[0] for o in offsets]
    todo = [(leg, f, o[f]) for leg, f, o in zip(legs, moved, offsets, strict=True) if len(f)]
    if not todo:
        return
    poles = [
        _knee_poles(
            grot[:, hip], gpos[:, hip], gpos[:, knee], gpos[:, ankle],
            None if toe is None else gpos[:, toe], f,
        )
        for (hip, knee, ankle, toe), f, _ in todo
    ]  # fmt: skip
    hip, knee, ankle = (np.concatenate([gpos[f, leg[k]] for leg, f, _ in todo]) for k in range(3))
    shift = np.concatenate([o for _, _, o in todo])
    target = _within_reach(hip, knee, ankle, ankle + shift)
    leg_ik = two_bone_ik(hip, knee, ankle, target, np.concatenate(poles), REACH_EPS)

    bounds = np.cumsum([0] + [len(f) for _, f, _ in todo])
    for (leg, f, _), start, stop in zip(todo, bounds[:-1], bounds[1:], strict=True):
        hip_turn, knee_turn = leg_ik.hip_turn[start:stop], leg_ik.knee_turn[start:stop]
        _turn_leg(lrot, grot, parents, leg, f, hip_turn, knee_turn)


def _turn_leg(
    lrot: np.ndarray,
    grot: np.ndarray,
    parents: np.ndarray,
    leg: tuple[int, int, int, int | None],
    f: np.ndarray,
    hip_turn: np.ndarray,
    knee_turn: np.ndarray,
) -> None:
    """``lrot``'s leg joints at frames ``f`` turned by an IK solution (world-frame turns
    of the thigh and, after it, the shin); the ankle keeps its global rotation."""
    hip, knee, ankle, _ = leg
    ik_kernels.turn_leg(
        lrot,
        np.ascontiguousarray(grot),
        np.asarray(parents, dtype=np.int64),
        np.array(_chain(parents, hip, knee), dtype=np.int64),
        np.array(_chain(parents, knee, ankle), dtype=np.int64),
        int(ankle),
        np.asarray(f, dtype=np.int64),
        np.ascontiguousarray(hip_turn, dtype=np.float64),
        np.ascontiguousarray(knee_turn, dtype=np.float64),
    )

"""A restyled canonical motion's feet put on the content's floor and held there (the
``foot_cleanup`` of the API), built on the leg IK of :mod:`motion.ik`: the body moved onto
the content's floor (:func:`ground_hips`), the content's planted feet held still there
(:func:`pin_canonical_feet`), feet in the air kept clear of it (:func:`lift_swing_feet`)
and toes turned up out of it (:func:`lift_toes`). The figures that chose each step:
docs/experiments/grounding.md.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from motion import canonical as C
from motion import contacts as CT
from motion import ik_kernels
from motion import kinematics as K
from motion.errors import MotionError
from motion.ik import leg_joints, move_ankles, pin_feet
from motion.skeleton import Motion

# The hips move onto a floor no faster than a Gaussian of this sigma lets them: slow
# enough to leave a gait's bob alone, fast enough to follow a crouch.
GROUNDING_SECONDS = 0.5
TOE_LIFT_SECONDS = 0.1  # Gaussian sigma of the ankle turn that lifts a dipping toe
# A foot in the air is raised to the content's height over its floor, up to this share of
# the leg (6.4 cm on the canonical body): lower, restyled feet skim the floor and slide.
SWING_CLEARANCE = 0.08
# Feet a restyled leg leaves under the content's floor, beyond where the floor lies on the
# whole (ground_hips), are brought up by bending the knees up to this share of the leg
# (8 cm), the hips raised only for the rest: the restyler pitches feet toe-down, and raising
# the whole body onto its toes put the hips 2-5 cm above the content's, which took the
# style's lower stance away.
KNEE_ABSORB = 0.10


CANONICAL_LEGS = [
    tuple(C.INDEX[f"{part}_{side}"] for part in ("UpperLeg", "LowerLeg", "Foot", "Toes"))
    for side in ("L", "R")
]


def pin_canonical_feet(
    motion: Motion,
    contacts: np.ndarray | None = None,
    floor_of: Motion | None = None,
    floor_positions: np.ndarray | None = None,
    **options,
) -> Motion:
    """:func:`pin_feet` for a canonical motion; ``contacts (F, 4)`` as
    :func:`contacts.canonical_foot_contacts` gives them (Foot_L, Toes_L, Foot_R, Toes_R),
    detected when not given. Flat feet are held in one orientation unless
    ``hold_flat_feet=False``.

    With ``floor_of`` (a canonical motion as long, the content a network restyled) the
    planted feet are put on that motion's floor by :func:`ground_hips` (the whole body
    moved onto it, then the knees bending where the feet sink under it by up to
    :data:`KNEE_ABSORB` of a leg more than on the whole), and the pins hold each
    contact's place on it, lifting a contact that sinks under its ground level but never
    pressing one down; after the pinning a toe that dips under that floor where
    ``contacts`` have it in the air is lifted onto it (:func:`lift_toes`).
    ``floor_positions``, when given, is ``contacts.canonical_foot_positions(floor_of)``.
    Contacts are never pressed down: that took the style away."""
    options.setdefault("hold_flat_feet", True)
    for m in (motion, floor_of):
        if m is not None and m.skeleton.names != C.JOINTS:
            raise MotionError("expected a motion on the canonical skeleton", kind="unusable")
    contacts = CT.canonical_foot_contacts(motion) if contacts is None else np.asarray(contacts)
    if contacts.shape != (motion.num_frames, 4):
        raise MotionError(f"contacts must be ({motion.num_frames}, 4), got {contacts.shape}")
    if floor_of is not None:
        if floor_of.num_frames != motion.num_frames:
            raise MotionError(
                f"the floor's motion has {floor_of.num_frames} frames, not {motion.num_frames}"
            )
        feet = CT.CANONICAL_FOOT_JOINTS
        gpos = CT.canonical_foot_positions(floor_of) if floor_positions is None else floor_positions
        found = CT.ground_heights(gpos, feet, C.leg_length())
        levels = dict(zip(feet, found.tolist(), strict=True))
        options["levels"] = levels
        if contacts.any():  # ground_hips, on the legs posed once for it and the pinning
            motion, options["posed"] = _grounded(
                motion, contacts, levels, C.INDEX["Hips"], GROUNDING_SECONDS,
                KNEE_ABSORB * C.leg_length(), leg_joints(CANONICAL_LEGS),
            )  # fmt: skip
            options["hold_height"] = False  # grounded: the pins hold the feet's places
    pinned = pin_feet(
        motion, contacts[:, [0, 2]], CANONICAL_LEGS, toe_contacts=contacts[:, [1, 3]], **options
    )
    if floor_of is None:
        return pinned
    cap = SWING_CLEARANCE * C.leg_length()
    clearance = np.minimum(np.maximum(gpos[:, feet, 1] - found[None], 0.0), cap)
    raised = lift_swing_feet(pinned, levels, contacts, clearance[:, [0, 2]])
    return lift_toes(raised, levels, contacts[:, [1, 3]], CANONICAL_LEGS, clearance[:, [1, 3]])


def _grounded(
    motion: Motion,
    contacts: np.ndarray,
    levels: dict[int, float],
    hips: int,
    sigma_seconds: float,
    absorb: float,
    joints: list[int],
) -> tuple[Motion, tuple[np.ndarray, np.ndarray]]:
    """:func:`ground_hips` (some frame must have a contact), and the forward kinematics of
    ``joints`` (:func:`kinematics.fk`'s) of the grounded motion: posed once, before, then
    shifted with the hips (their root only turns about the vertical, so a rise of the
    hips raises every joint below them by as much)."""
    parents = motion.skeleton.parents
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=joints)
    shift = _grounding_shift(gpos, contacts, levels, sigma_seconds * motion.fps, absorb)
    lpos = motion.lpos.copy()
    lpos[:, hips, 1] += shift
    posed = np.flatnonzero(K.with_ancestors(parents, joints))
    below_hips = [j for j in posed if K.with_ancestors(parents, [j])[hips]]
    gpos[:, below_hips, 1] += shift[:, None]
    return motion.replace(lpos=lpos), (grot, gpos)


def _widened_smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    """``x (F,)`` widened by a running maximum over 4 sigma, then Gaussian-smoothed: a
    peak's frame keeps (almost) its whole value and the change ramps in and out."""
    size = 2 * int(np.ceil(2 * sigma)) + 1
    return gaussian_filter1d(maximum_filter1d(x, size, mode="nearest"), sigma, mode="nearest")


def lift_swing_feet(
    motion: Motion,
    levels: dict[int, float],
    contacts: np.ndarray,
    clearance: np.ndarray,
    sigma_seconds: float = TOE_LIFT_SECONDS,
) -> Motion:
    """A canonical ``motion`` with each ankle that hangs lower over its ground level in
    ``levels`` than ``clearance (F, 2)`` (left, right) while ``contacts (F, 4)`` (as
    :func:`pin_canonical_feet`'s) have its heel and toe in the air raised to it by leg IK,
    smoothly (Gaussian, ``sigma_seconds``); planted frames are left alone.

    A restyled leg often swings its foot lower than the content's: the foot then skims
    the floor, which reads as sliding."""
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (motion.num_frames, 4) or clearance.shape != (motion.num_frames, 2):
        raise MotionError(f"contacts (F, 4) and clearance (F, 2) for {motion.num_frames} frames")
    parents = motion.skeleton.parents
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=leg_joints(CANONICAL_LEGS))
    lrot = motion.lrot.copy()
    sigma = sigma_seconds * motion.fps
    offsets = []
    for i, leg in enumerate(CANONICAL_LEGS):
        ankle = leg[2]
        planted = contacts[:, 2 * i] | contacts[:, 2 * i + 1]
        low = np.clip(levels[ankle] + clearance[:, i] - gpos[:, ankle, 1], 0.0, None)
        low[planted] = 0.0
        lift = _widened_smooth(low, sigma)
        lift[planted | (lift < 1e-6)] = 0.0
        offsets.append(np.zeros((motion.num_frames, 3)))
        offsets[-1][:, 1] = lift
    move_ankles(lrot, grot, gpos, parents, CANONICAL_LEGS, offsets)
    return motion.replace(lrot=lrot)


def lift_toes(
    motion: Motion,
    levels: dict[int, float],
    toe_contacts: np.ndarray,
    legs: list[tuple[int, int, int, int | None]],
    clearance: np.ndarray | None = None,
    sigma_seconds: float = TOE_LIFT_SECONDS,
) -> Motion:
    """``motion`` with each toe that dips under its ground level in ``levels`` (joint ->
    height; plus ``clearance (F, len(legs))`` when given) while ``toe_contacts (F,
    len(legs))`` have it in the air turned up onto it by
    its ankle, smoothly (Gaussian, ``sigma_seconds``); ankles stay where they are, and
    planted toes are left to :func:`pin_feet` but for the ramp into and out of a dip
    next to them. The translator's decoder pitches some feet
    toe-down, and toes that swung through the floor and were then found in contact on the
    output slid. Planted toes are not lifted: they would then touch the floor and turn
    with the ankle."""
    toe_contacts = np.asarray(toe_contacts, dtype=bool)
    if toe_contacts.shape != (motion.num_frames, len(legs)):
        raise MotionError(
            f"toe contacts must be ({motion.num_frames}, {len(legs)}), got {toe_contacts.shape}"
        )
    parents = motion.skeleton.parents
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents, joints=leg_joints(legs))
    lrot = motion.lrot.copy()
    for i, (_, _, ankle, toe) in enumerate(legs):
        if toe is None:
            continue
        air = ~toe_contacts[:, i]
        under = np.where(air, np.clip(levels[toe] - gpos[:, toe, 1], 0, None), 0.0)
        sigma = sigma_seconds * motion.fps
        lift = _widened_smooth(under, sigma)  # a dip's deepest frame lifted (almost) whole
        if clearance is not None:  # the rest of the way up to it, in the air only
            short = np.where(
                air, np.clip(levels[toe] + clearance[:, i] - gpos[:, toe, 1], 0, None), 0.0
            )
            extra = _widened_smooth(short - under, sigma)
            lift += np.where(air, extra, 0.0)
        f = np.nonzero(lift > 1e-6)[0]
        if not len(f):
            continue
        ik_kernels.lift_toes(
            lrot, grot, gpos, f.astype(np.int64), lift, int(parents[ankle]), ankle, toe
        )
    return motion.replace(lrot=lrot)


def ground_hips(
    motion: Motion,
    contacts: np.ndarray,
    levels: dict[int, float],
    hips: int,
    sigma_seconds: float = GROUNDING_SECONDS,
    absorb: float = 0.0,
) -> Motion:
    """``motion`` with ``hips`` raised or lowered, slowly, so that the lowest of its foot
    joints in contact stands on its ground level in ``levels`` (foot joint -> height;
    ``contacts (F, len(levels))`` in that order). ``hips`` must hang from a root that
    only turns about the vertical, as the canonical Hips does. Frames with no contact
    take their neighbours' shift. The shift's median over the clip moves the hips whole:
    it is where the floor lies against the motion's, which says nothing of its style
    (foreign clips' floors lie 12 cm under to 8 cm over Bandai's, which the restyler
    learned on). Of the rest, feet under the floor by less than ``absorb`` leave the hips
    where they are (the caller's leg IK brings those feet up), and by more raise them by
    the rest. (Holding the lowest joint, not the mean of them, sank the toes less and read
    1.4 points more in the target style.)

    A decoder given the content's hips height may straighten or bend the legs (its
    style, or the habits of the skeletons it learned on): on one Xia walk that put the
    toes 27 cm under the floor, and leg IK cannot lift them out without bending the
    knees the style straightened."""
    contacts = np.asarray(contacts, dtype=bool)
    feet = list(levels)
    if contacts.shape != (motion.num_frames, len(feet)):
        raise MotionError(
            f"contacts must be ({motion.num_frames}, {len(feet)}), got {contacts.shape}"
        )
    if not contacts.any():
        return motion
    return _grounded(motion, contacts, levels, hips, sigma_seconds, absorb, feet)[0]


def _grounding_shift(
    gpos: np.ndarray, contacts: np.ndarray, levels: dict[int, float], sigma: float, absorb: float
) -> np.ndarray:
    """:func:`ground_hips`'s vertical shift ``(F,)`` of the hips, from the foot joints'
    positions ``gpos (F, J, 3)``; ``sigma`` in frames; some frame must have a contact."""
    feet = list(levels)
    held = contacts.any(axis=1)
    gap = np.array([levels[j] for j in feet])[None] - gpos[:, feet, 1]
    frames = np.arange(len(gpos))
    lowest = np.where(contacts, gap, -np.inf).max(axis=1)
    offset = float(np.median(lowest[held]))  # where the floor lies: one translation
    shift = np.interp(frames, frames[held], lowest[held] - offset)
    shift = gaussian_filter1d(shift, sigma, mode="nearest")
    return offset + np.where(shift > 0.0, np.maximum(shift - absorb, 0.0), shift)

"""The foot clean-up of canonical motions (motion.grounding): the body moved onto a floor,
feet pinned on another clip's floor, knees bent for sunk feet, toes and swinging feet
lifted."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh, grounding, ik, retarget
from motion import canonical as C
from motion import contacts as CT
from motion import kinematics as K
from motion.errors import MotionError
from motion.skeleton import Motion
from tests.conftest import data_path
from tests.rigs import FIXTURE

WALK = ("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh")


@pytest.fixture(scope="module")
def walk() -> Motion:
    return retarget.to_canonical(bvh.load(data_path(*WALK)))


@pytest.fixture(scope="module")
def fixture_walk() -> Motion:
    """The repository's own CMU walk on the canonical skeleton (no shared data needed)."""
    return retarget.to_canonical(bvh.load(FIXTURE))


def _foot_levels(motion: Motion) -> np.ndarray:
    gpos = K.global_positions(motion)
    return CT.ground_heights(gpos, CT.CANONICAL_FOOT_JOINTS, C.leg_length())


def _hips_raised(motion: Motion, by: np.ndarray | float) -> Motion:
    lpos = motion.lpos.copy()
    lpos[:, C.INDEX["Hips"], 1] += by
    return motion.replace(lpos=lpos)


@pytest.mark.parametrize("by", [-12.0, 8.0])  # feet sunk into the floor, feet floating
def test_ground_hips_puts_planted_feet_back_on_the_floor(fixture_walk, by):
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    hips = C.INDEX["Hips"]
    moved = _hips_raised(fixture_walk, by)
    grounded = grounding.ground_hips(moved, contacts, levels, hips)
    # the error is removed whole: the same result as from the clip itself...
    settled = grounding.ground_hips(fixture_walk, contacts, levels, hips)
    np.testing.assert_allclose(grounded.lpos, settled.lpos, atol=1e-6)
    np.testing.assert_array_equal(grounded.lrot, moved.lrot)  # only the hips' height moves
    # ...which stands where it stood, to within the heights its planted feet vary by
    np.testing.assert_allclose(_foot_levels(grounded), _foot_levels(fixture_walk), atol=1.5)
    assert np.abs(settled.lpos[:, hips, 1] - fixture_walk.lpos[:, hips, 1]).max() < 2.5  # cm


def test_ground_hips_follows_a_slow_crouch(fixture_walk):
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    hips = C.INDEX["Hips"]
    crouch = np.linspace(0.0, -15.0, fixture_walk.num_frames)  # legs 15 cm too long by the end
    grounded = grounding.ground_hips(_hips_raised(fixture_walk, crouch), contacts, levels, hips)
    settled = grounding.ground_hips(fixture_walk, contacts, levels, hips)
    error = np.abs(grounded.lpos[:, hips, 1] - settled.lpos[:, hips, 1])
    middle = slice(len(error) // 4, -len(error) // 4)
    assert error[middle].max() < 0.75 and error.max() < 2.5  # cm, against 15 uncorrected
    none = np.zeros_like(contacts)
    np.testing.assert_array_equal(
        grounding.ground_hips(fixture_walk, none, levels, hips).lpos, fixture_walk.lpos
    )
    with pytest.raises(MotionError, match="contacts must be"):
        grounding.ground_hips(fixture_walk, contacts[:, :3], levels, hips)


def test_feet_pinned_on_the_floor_of_another_clip(fixture_walk):
    """A decoder's straighter legs under the content's hips height sink the feet; pinned on
    the content's floor they stand on it again, and still hold still."""
    contacts = CT.canonical_foot_contacts(fixture_walk)
    sunk = _hips_raised(fixture_walk, -10.0)
    own = grounding.pin_canonical_feet(sunk, contacts)
    grounded = grounding.pin_canonical_feet(sunk, contacts, floor_of=fixture_walk)
    assert (_foot_levels(own) - _foot_levels(fixture_walk)).mean() < -8.0
    np.testing.assert_allclose(_foot_levels(grounded), _foot_levels(fixture_walk), atol=1.0)
    assert (
        CT.canonical_foot_skating(grounded, contacts)
        <= CT.canonical_foot_skating(own, contacts) + 0.1
    )
    with pytest.raises(MotionError, match="frames"):
        grounding.pin_canonical_feet(sunk, contacts, floor_of=fixture_walk.slice(1))


def _dip(motion: Motion, depth: float) -> np.ndarray:
    """A sink of ``depth`` over the middle third of ``motion``'s frames: less than half of
    them, so the floor still lies where it did for the clip as a whole."""
    dip = np.zeros(motion.num_frames)
    third = motion.num_frames // 3
    dip[third : 2 * third] = depth
    return dip


@pytest.mark.parametrize("by", [-3.0, 3.0, 12.0])  # cm: floating, sunk less, more than absorb
def test_ground_hips_moves_a_whole_clip_onto_the_floor(fixture_walk, by):
    """A clip under or over the floor throughout says where the floor lies, not how the
    body stands: it moves whole, none of it left to the knees."""
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    hips = C.INDEX["Hips"]
    moved = _hips_raised(fixture_walk, -by)
    kept = grounding.ground_hips(moved, contacts, levels, hips, absorb=6.0)
    np.testing.assert_allclose(  # as from the clip itself
        kept.lpos,
        grounding.ground_hips(fixture_walk, contacts, levels, hips, absorb=6.0).lpos,
        atol=1e-6,
    )


@pytest.mark.parametrize("by", [6.0, 30.0])  # cm: the knees take all of it, 6 cm of it
def test_ground_hips_leaves_a_passing_sink_to_the_knees(fixture_walk, by):
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    hips, absorb = C.INDEX["Hips"], 6.0
    dip = _dip(fixture_walk, by)
    sunk = _hips_raised(fixture_walk, -dip)
    whole = (
        grounding.ground_hips(sunk, contacts, levels, hips).lpos[:, hips, 1] - sunk.lpos[:, hips, 1]
    )
    kept = grounding.ground_hips(sunk, contacts, levels, hips, absorb=absorb)
    raised = kept.lpos[:, hips, 1] - sunk.lpos[:, hips, 1]
    knees = whole - raised  # what is left to the knees
    assert knees.min() > -1e-9 and knees.max() < absorb + 1e-9
    middle = fixture_walk.num_frames // 2
    if by < 2 * absorb:  # the dip, smoothed over the grounding's half second, under absorb
        assert knees[middle] > 1.5
        assert np.ptp(raised[dip > 0]) < 1e-9  # the hips do not rise for it
    else:
        np.testing.assert_allclose(knees[middle], absorb, atol=1e-9)


def test_sunk_feet_reach_the_contents_floor_with_bent_knees(fixture_walk):
    """A restyled body lower than the content for a while keeps its height there: its
    planted feet come up onto the content's floor by leg IK, the knees bending more."""
    contacts = CT.canonical_foot_contacts(fixture_walk)
    knee = C.INDEX["LowerLeg_L"]
    low = _hips_raised(
        fixture_walk, -_dip(fixture_walk, 0.5 * grounding.KNEE_ABSORB * C.leg_length())
    )
    out = grounding.pin_canonical_feet(low, contacts, floor_of=fixture_walk)
    own = grounding.pin_canonical_feet(fixture_walk, contacts, floor_of=fixture_walk)
    hips = C.INDEX["Hips"]
    # in the dip the hips stay lower than the content's cleaned up alike
    middle = fixture_walk.num_frames // 2
    assert (own.lpos - out.lpos)[middle, hips, 1] > 1.5
    np.testing.assert_allclose(_foot_levels(out), _foot_levels(fixture_walk), atol=1.0)

    def bend(m):  # the angle between the left thigh and shin, degrees, in the dip
        g = K.global_positions(m)[_dip(m, 1.0) > 0]
        thigh = g[:, C.INDEX["UpperLeg_L"]] - g[:, knee]
        shin = g[:, C.INDEX["Foot_L"]] - g[:, knee]
        cos = (
            np.sum(thigh * shin, -1)
            / np.linalg.norm(thigh, axis=-1)
            / np.linalg.norm(shin, axis=-1)
        )
        return 180.0 - np.degrees(np.arccos(np.clip(cos, -1, 1))).mean()

    assert bend(out) > bend(own) + 3.0


def test_a_toe_dipping_in_the_air_is_lifted_onto_the_floor(fixture_walk):
    """A floor 6 cm over the walk's toe level: every toe in the air within 6 cm of the real
    floor dips under it. The ankles turn the dipping toes up onto it; nothing else moves."""
    contacts = CT.canonical_foot_contacts(fixture_walk)
    toes = contacts[:, [1, 3]]
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk) + 6.0, strict=True))
    lifted = grounding.lift_toes(fixture_walk, levels, toes, grounding.CANONICAL_LEGS)
    before, after = K.global_positions(fixture_walk), K.global_positions(lifted)
    toe_joints = [C.INDEX["Toes_L"], C.INDEX["Toes_R"]]
    others = [j for j in range(len(C.JOINTS)) if j not in toe_joints]
    np.testing.assert_allclose(after[:, others], before[:, others], atol=1e-6)  # ankles too
    for i, (_, _, ankle, toe) in enumerate(grounding.CANONICAL_LEGS):
        np.testing.assert_allclose(  # the foot keeps its length
            np.linalg.norm(after[:, toe] - after[:, ankle], axis=-1),
            np.linalg.norm(before[:, toe] - before[:, ankle], axis=-1),
            rtol=1e-6,
        )
        assert (after[:, toe, 1] >= before[:, toe, 1] - 1e-6).all()  # never pushed down
        dip = np.clip(levels[toe] - before[:, toe, 1], 0, None) * ~toes[:, i]
        left = np.clip(levels[toe] - after[:, toe, 1], 0, None) * ~toes[:, i]
        assert dip.sum() > 20.0  # cm over the clip: the case is real
        assert left.sum() < 0.05 * dip.sum()  # smoothed, so the edges of a dip keep a little
    nothing = {j: level - 50.0 for j, level in levels.items()}
    same = grounding.lift_toes(fixture_walk, nothing, toes, grounding.CANONICAL_LEGS)
    np.testing.assert_array_equal(same.lrot, fixture_walk.lrot)
    with pytest.raises(MotionError, match="toe contacts"):
        grounding.lift_toes(fixture_walk, levels, toes[1:], grounding.CANONICAL_LEGS)


def test_a_swinging_foot_skimming_the_floor_is_raised_to_the_contents_clearance(fixture_walk):
    """The walk's hips lowered by 5 cm: its feet in the air skim (or sink under) the floor.
    Against the walk as the floor and clearance (capped at SWING_CLEARANCE of the leg), the
    swinging ankles come back up to it; planted frames are untouched."""
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    walk = K.global_positions(fixture_walk)
    feet = CT.CANONICAL_FOOT_JOINTS
    cap = grounding.SWING_CLEARANCE * C.leg_length()
    clearance = np.minimum(walk[:, feet, 1] - _foot_levels(fixture_walk)[None], cap)
    low = _hips_raised(fixture_walk, -5.0)
    raised = grounding.lift_swing_feet(low, levels, contacts, clearance[:, [0, 2]])
    before, after = K.global_positions(low), K.global_positions(raised)
    for i, (_, _, ankle, _) in enumerate(grounding.CANONICAL_LEGS):
        planted = contacts[:, 2 * i] | contacts[:, 2 * i + 1]
        np.testing.assert_allclose(after[planted, ankle], before[planted, ankle], atol=1e-6)
        want = levels[ankle] + clearance[:, i]
        short_before = np.clip(want - before[:, ankle, 1], 0, None)[~planted]
        short_after = np.clip(want - after[:, ankle, 1], 0, None)[~planted]
        assert short_before.sum() > 20.0  # cm over the clip: the case is real
        assert short_after.sum() < 0.1 * short_before.sum()  # edges of a swing keep a little
        assert (after[:, ankle, 1] >= before[:, ankle, 1] - 1e-6).all()  # never pushed down
        np.testing.assert_allclose(  # only up: the foot's path over the floor stays
            after[:, ankle][:, [0, 2]], before[:, ankle][:, [0, 2]], atol=0.5
        )
    with pytest.raises(MotionError, match="clearance"):
        grounding.lift_swing_feet(low, levels, contacts, clearance[1:, [0, 2]])


def test_pins_without_hold_height_lift_sunk_contacts_and_never_press_floating_ones(fixture_walk):
    contacts = CT.canonical_foot_contacts(fixture_walk)
    levels = dict(zip(CT.CANONICAL_FOOT_JOINTS, _foot_levels(fixture_walk), strict=True))
    legs, planted = grounding.CANONICAL_LEGS, contacts[:, [0, 2]]
    ankles = [C.INDEX["Foot_L"], C.INDEX["Foot_R"]]

    def ankle_heights(m):
        return K.global_positions(m)[:, ankles, 1][planted]

    for by, moves in ((3.0, False), (-3.0, True)):  # floating: left; sunk: lifted
        moved = _hips_raised(fixture_walk, by)
        held = ik.pin_feet(moved, planted, legs, levels=levels)
        kept = ik.pin_feet(moved, planted, legs, levels=levels, hold_height=False)
        before = ankle_heights(moved).mean()
        assert abs(ankle_heights(held).mean() - before) > 1.5  # held: brought to the floor
        if moves:
            assert ankle_heights(kept).mean() > before + 1.0
        else:
            assert ankle_heights(kept).mean() == pytest.approx(before, abs=0.3)

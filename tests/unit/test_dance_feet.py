"""The dance's feet (motion.dance_feet): contacts predicted from the motion, feet planted."""

from __future__ import annotations

import numpy as np
import pytest

from motion import canonical as C
from motion import contacts as CT
from motion import dance_feet as FT
from motion import kinematics as K
from motion import retarget
from tests.rigs import load_fixture

HIPS = C.INDEX["Hips"]


@pytest.fixture(scope="module")
def gliding_walk():
    """A real walk (2 s) whose body travels 1.4 times as far as its steps carry it: the
    planted feet glide along the floor, as the dance network's do."""
    m = load_fixture()
    walk = retarget.to_canonical(m, retarget.make_rig(m.skeleton, m))
    lpos = walk.lpos.copy()
    floor = lpos[:, HIPS][:, [0, 2]]
    lpos[:, HIPS, 0] = floor[0, 0] + 1.4 * (floor[:, 0] - floor[0, 0])
    lpos[:, HIPS, 2] = floor[0, 1] + 1.4 * (floor[:, 1] - floor[0, 1])
    return walk, walk.replace(lpos=lpos)


def _feet_still(gpos: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(F, 22, 3)`` with only the feet set: the left one sliding at 1 m/s for the
    first second while the right one stands, then the other way round."""
    frames = int(2 * fps)
    gpos = np.zeros((frames, len(C.JOINTS), 3))
    t = np.arange(frames) / fps
    left, right = np.minimum(t, 1.0) * 100.0, np.maximum(t - 1.0, 0.0) * 100.0
    for joint, x, z in (("Foot_L", left, 10.0), ("Toes_L", left + 15, 10.0),
                        ("Foot_R", right, -10.0), ("Toes_R", right + 15, -10.0)):  # fmt: skip
        gpos[:, C.INDEX[joint], 0] = x
        gpos[:, C.INDEX[joint], 1] = 8.0 if "Foot" in joint else 2.0
        gpos[:, C.INDEX[joint], 2] = z
    return gpos, t


def test_the_support_is_the_slower_foot_and_someone_always_stands():
    gpos, t = _feet_still(None, 30.0)
    contacts = FT.predict_contacts(gpos, 30.0)
    left, right = contacts[:, :2].any(axis=1), contacts[:, 2:].any(axis=1)
    assert (left | right).all()
    inner_first, inner_second = (t > 0.1) & (t < 0.9), (t > 1.1) & (t < 1.9)
    assert right[inner_first].all() and not left[inner_first].any()
    assert left[inner_second].all() and not right[inner_second].any()
    # heel and toe both down when the foot is flat (heights over their own ground levels)
    np.testing.assert_array_equal(contacts[:, 0], contacts[:, 1])


def test_the_networks_contacts_are_kept():
    gpos, t = _feet_still(None, 30.0)
    network = np.zeros((len(gpos), 4), dtype=bool)
    network[5:20, 1] = True  # the network stands the sliding left foot on its toes
    contacts = FT.predict_contacts(gpos, 30.0, network)
    assert contacts[5:20, :2].any(axis=1).all()
    assert not contacts[22:28, :2].any()


def test_a_gliding_walk_is_planted(gliding_walk):
    walk, glide = gliding_walk
    out = FT.clean_feet(glide)
    before, after = K.global_positions(glide), K.global_positions(out)
    assert CT.canonical_foot_sliding(glide) > 2.0 * CT.canonical_foot_sliding(walk)
    assert CT.canonical_foot_sliding(out) < 0.5 * CT.canonical_foot_sliding(walk)
    contacts = FT.predict_contacts(before, glide.fps)
    # a flat foot in contact holds still on the floor
    for i, joint in enumerate(FT.FEET):
        held = contacts[1:, i] & contacts[:-1, i] & contacts[1:, i ^ 1] & contacts[:-1, i ^ 1]
        step = np.linalg.norm(np.diff(after[:, joint][:, [0, 2]], axis=0), axis=-1)
        assert held.sum() > 5 and step[held].max() < 0.05, C.JOINTS[joint]
    # a foot in the air clears the floor along its swing's arc (the lift's smoothing takes a
    # little off where the foot comes down fast)
    levels = FT.floor_levels(before, contacts)
    for side in (0, 1):
        planted = contacts[:, 2 * side] | contacts[:, 2 * side + 1]
        arc = FT.swing_arc(planted, glide.fps)
        free = arc > 0.5
        low = after[:, FT.FEET[2 * side : 2 * side + 2], 1] - levels[2 * side : 2 * side + 2]
        assert free.any()
        assert (low[free].min(axis=1) > 0.6 * FT.CLEARANCE * FT.LEG * arc[free]).all()
    # the body travels as far as its steps carry it (the walk's path), not the glide's
    travel = [K.global_positions(m)[-1, HIPS] - K.global_positions(m)[0, HIPS] for m in (walk, out)]
    walked, carried = (np.linalg.norm(t[[0, 2]]) for t in travel)
    assert abs(carried - walked) < 0.1 * walked, (carried, walked)
    np.testing.assert_allclose(out.lrot[:, C.INDEX["Spine"]], glide.lrot[:, C.INDEX["Spine"]])
    bones = [np.linalg.norm(p[:, 2:] - p[:, C.PARENTS[2:]], axis=-1) for p in (before, after)]
    np.testing.assert_allclose(bones[1], bones[0], atol=1e-6)


def test_a_foot_leaves_the_floor_in_an_arc_without_a_jump(gliding_walk):
    """A still pose whose left foot stands on frames 0-9 and 30-39: between them the foot
    rises and comes down along the swing's arc, highest mid-swing, never rising or falling
    faster than the arc does (the lift once reached its full clearance within two frames
    of the lift-off)."""
    walk, _ = gliding_walk
    frames = 40
    pose = walk.slice(0, 1)
    still = pose.replace(lrot=np.repeat(pose.lrot, frames, axis=0),
                         lpos=np.repeat(pose.lpos, frames, axis=0))  # fmt: skip
    contacts = np.zeros((frames, 4), dtype=bool)
    contacts[:10, :2] = contacts[30:, :2] = True  # the left foot's two stances
    contacts[:, 2:] = True  # the right foot stands throughout
    before = K.global_positions(still)
    levels = {j: float(before[0, j, 1]) for j in FT.FEET}  # the feet stand on their floor
    after = K.global_positions(FT.lift_free_feet(still, levels, contacts))
    lift = after[:, C.INDEX["Foot_L"], 1] - before[:, C.INDEX["Foot_L"], 1]
    peak = FT.CLEARANCE * FT.LEG
    assert abs(int(np.argmax(lift)) - 19.5) <= 1 and lift.max() > 0.9 * peak
    steepest = np.pi / 20 * peak  # the arc's slope per frame over a 20-frame swing
    assert np.abs(np.diff(lift)).max() <= 1.05 * steepest
    assert np.abs(lift[:7]).max() < 0.05 * peak and np.abs(lift[33:]).max() < 0.05 * peak
    np.testing.assert_allclose(after[:, C.INDEX["Foot_R"]], before[:, C.INDEX["Foot_R"]], atol=1e-6)


def test_a_dance_in_place_travels_over_its_planted_feet(gliding_walk):
    """The dance network learnt in place: its standing foot slides back under the hips.
    The clean-up carries the body forward over it instead, the way the dancer went."""
    walk, _ = gliding_walk
    lpos = walk.lpos.copy()
    lpos[:, HIPS, [0, 2]] = lpos[:1, HIPS, [0, 2]]
    in_place = walk.replace(lpos=lpos)
    out = FT.clean_feet(in_place)
    walked = K.global_positions(walk)[-1, HIPS] - K.global_positions(walk)[0, HIPS]
    carried = K.global_positions(out)[-1, HIPS] - K.global_positions(out)[0, HIPS]
    walked, carried = walked[[0, 2]], carried[[0, 2]]
    cosine = walked @ carried / (np.linalg.norm(walked) * np.linalg.norm(carried))
    assert cosine > 0.95 and np.linalg.norm(carried) > 0.6 * np.linalg.norm(walked)
    assert CT.canonical_foot_sliding(out) < 0.3 * CT.canonical_foot_sliding(in_place)


def test_travel_holds_a_planted_foot(gliding_walk):
    """A standing pose sliding back at 50 cm/s on its planted left foot is carried forward
    by as much: the foot stays put."""
    walk, _ = gliding_walk
    frames = walk.num_frames
    lpos = np.repeat(walk.lpos[:1], frames, axis=0)
    lpos[:, HIPS, 0] -= 50.0 * np.arange(frames) / walk.fps
    sliding = walk.replace(lrot=np.repeat(walk.lrot[:1], frames, axis=0), lpos=lpos)
    contacts = np.zeros((frames, 4), dtype=bool)
    contacts[:, :2] = True
    out = FT.travel_on_support(sliding, contacts)
    foot = K.global_positions(out)[:, C.INDEX["Foot_L"]]
    assert np.ptp(foot[:, 0]) < 1e-6 and np.ptp(foot[:, 2]) < 1e-6


def test_no_motion_no_contacts():
    assert FT.predict_contacts(np.zeros((0, len(C.JOINTS), 3)), 30.0).shape == (0, 4)

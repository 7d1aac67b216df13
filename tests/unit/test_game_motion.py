"""Game invariants at the motion level: loops, leading reference frames, hinges, speed,
root motion in place; on real files where there are any."""

from __future__ import annotations

import numpy as np
import pytest

from motion import anatomy, bvh, loops, reference, retarget, root_motion
from motion import canonical as C
from motion import kinematics as K
from motion import rotations as R
from motion.features import time_warp
from tests import rigs
from tests.conftest import data_path

H = C.body_height()


def canonical(motion, fps=C.FPS):
    return retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion), fps=fps)


@pytest.fixture(scope="module")
def walk():
    return canonical(rigs.walk_cycle())


# --- loops ---------------------------------------------------------------------------------


def test_a_closed_walk_cycle_is_found_closed_and_without_its_last_frame_open(walk):
    loop = loops.detect(walk)
    assert loop is not None and loop.closed and loop.gap < 1e-6
    open_loop = loops.detect(walk.slice(0, -1))
    assert open_loop is not None and not open_loop.closed
    assert 0.5 < open_loop.gap <= loops.OPEN_GAP


def test_a_foreign_take_is_no_loop_unless_the_client_says_so():
    take = canonical(bvh.load(data_path("cmu-31", "02_01.bvh")).slice(1))
    assert loops.detect(take) is None
    forced = loops.detect(take, force=True)
    assert forced is not None and not forced.closed


def test_closing_an_open_cycle_adds_the_first_frame_one_cycle_on(walk):
    opened = walk.slice(0, -1)
    closed = loops.closed(opened, loops.detect(opened))
    assert closed.num_frames == walk.num_frames
    gap = np.linalg.norm(K.global_positions(closed)[-1] - K.global_positions(walk)[-1], axis=-1)
    assert gap.max() < 0.01 * H


def test_a_cycle_extended_and_cropped_is_itself_and_runs_on_smoothly(walk):
    cycle = loops.Cycle.of(walk, margin=50)
    extended = cycle.extended(walk)
    assert extended.num_frames == walk.num_frames + 100
    local = loops.local_poses(extended)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    assert steps.max() < 1.5 * np.median(steps)  # no jump where one copy meets the next
    hips = K.global_positions(extended)[:, C.INDEX["Hips"]]
    assert np.all(np.diff(hips[:, 2]) > 0)  # the copies walk on, not back to the start
    back = cycle.cropped(extended)
    assert np.abs(K.global_positions(back) - K.global_positions(walk)).max() < 1e-9


def test_cropping_spreads_what_a_processed_cycle_lost_at_its_ends(walk):
    cycle = loops.Cycle.of(walk, margin=10)
    extended = cycle.extended(walk)
    lrot = extended.lrot.copy()
    drift = np.linspace(0.0, 0.4, extended.num_frames)  # a bend that grows over the clip
    knee = C.INDEX["LowerLeg_L"]
    lrot[:, knee] = R.mul(R.from_rotvec(drift[:, None] * [1.0, 0.0, 0.0]), lrot[:, knee])
    processed = extended.replace(lrot=lrot)
    raw = processed.slice(10, 10 + walk.num_frames)
    jump, step = loops.loop_jump(raw)
    assert jump > 0.5 * step  # as cut, it pops
    jump, step = loops.loop_jump(cycle.cropped(processed))
    assert jump < 1e-9 * H


@pytest.mark.parametrize(
    ("take", "closed"),
    [("dash_normal_001", False), ("run_normal_001", True), ("walk-back_normal_001", True),
     ("walk_normal_002", True)],
)  # fmt: skip
def test_bandais_authored_cycles_are_found(take, closed):
    """Held back: no Bandai cycle chose the tolerances (their travel is on joint_Root)."""
    motion = bvh.load(data_path("bandai", "dataset-1", f"dataset-1_{take}.bvh"))
    loop = loops.detect(canonical(motion, None))
    assert loop is not None and loop.closed == closed


# --- reference frames ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("parts", "count"),
    [
        (("cmu-31", "02_01.bvh"), 1),
        (("cmu-31", "07_12.bvh"), 2),
        (("cmu-31", "09_01.bvh"), 1),
        (("cmu-dance-43", "05_20.bvh"), 1),  # held back: another rig, not among those chosen on
    ],
)
def test_cmu_t_pose_frames_are_found(parts, count):
    motion = bvh.load(data_path(*parts))
    rig = retarget.make_rig(motion.skeleton, motion)
    full = retarget.to_canonical(motion, rig, fps=None)
    assert reference.leading_reference_frames(full, reference.rest_on_canonical(rig, 120)) == count


@pytest.mark.parametrize(
    "parts", [("xia", "angry_13_000.bvh"), ("cmu-dance-43", "60_01_scaled.bvh")]
)
def test_takes_that_start_in_motion_have_none(parts):
    motion = bvh.load(data_path(*parts))
    rig = retarget.make_rig(motion.skeleton, motion)
    full = retarget.to_canonical(motion, rig, fps=None)
    assert reference.leading_reference_frames(full, reference.rest_on_canonical(rig, 120)) == 0


def test_a_t_pose_put_before_a_walk_is_found():
    walk = rigs.load_fixture()
    rest = walk.slice(0, 1).replace(lrot=R.identity((1, walk.skeleton.num_joints)))
    with_pose = walk.replace(lrot=np.concatenate([rest.lrot, walk.lrot]),
                             lpos=np.concatenate([walk.lpos[:1], walk.lpos]))  # fmt: skip
    for motion, count in ((walk, 0), (with_pose, 1)):
        rig = retarget.make_rig(motion.skeleton, motion)
        rest = reference.rest_on_canonical(rig, motion.fps)
        assert reference.leading_reference_frames(canonical(motion, None), rest) == count


# --- hinges and speed ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def bandai():
    return canonical(bvh.load(data_path("bandai", "dataset-2", "dataset-2_walk_normal_001.bvh")))


def test_real_mocap_keeps_its_knees_and_barely_changes_under_the_hinges(bandai):
    assert not anatomy.knees_backwards(bandai).any()
    moved = K.global_positions(anatomy.hinged(bandai)) - K.global_positions(bandai)
    assert np.linalg.norm(moved, axis=-1).max() < 0.005 * H


def test_a_knee_bent_the_wrong_way_is_seen_and_straightened(bandai):
    lrot = bandai.lrot.copy()
    for name in anatomy.KNEES:
        j = C.INDEX[name]
        flexion = 2 * np.arctan2(lrot[:, j, 0], lrot[:, j, 3])  # about the thigh's X
        lrot[:, j] = R.mul(R.from_rotvec((-2 * flexion)[:, None] * [1.0, 0.0, 0.0]), lrot[:, j])
    reversed_knees = bandai.replace(lrot=lrot)
    assert anatomy.knees_backwards(reversed_knees).mean() > 0.5
    fixed = anatomy.hinged(reversed_knees)
    assert not anatomy.knees_backwards(fixed).any()


def test_a_knee_swung_behind_its_leg_is_swivelled_forward_with_the_foot_held(walk):
    """What a leg IK can do to a bent knee (the hinge itself fine): the leg turned about its
    hip-ankle line until the knee points back. The swivel turns it forward again without
    moving the ankle, the foot or the bend, and leaves the other frames alone."""
    walk = walk.replace(lrot=np.tile(walk.lrot, (3, 1, 1)), lpos=np.tile(walk.lpos, (3, 1, 1)))
    grot, gpos = K.fk(walk.lrot, walk.lpos, walk.skeleton.parents)
    hip, knee, foot = (C.INDEX[n] for n in ("UpperLeg_L", "LowerLeg_L", "Foot_L"))
    turned = np.zeros(walk.num_frames, dtype=bool)
    turned[40:50] = True
    line = gpos[turned, foot] - gpos[turned, hip]
    q = R.from_rotvec(np.pi * line / np.linalg.norm(line, axis=-1, keepdims=True))
    lrot = walk.lrot.copy()
    parent = int(walk.skeleton.parents[hip])
    lrot[turned, hip] = R.mul(R.inv(grot[turned, parent]), R.mul(q, grot[turned, hip]))
    lrot[turned, foot] = R.mul(R.inv(R.mul(q, grot[turned, knee])), grot[turned, foot])
    swung = walk.replace(lrot=lrot)
    assert not anatomy.knees_backwards(walk).any()
    assert anatomy.knees_backwards(swung)[turned].sum() >= 5

    fixed = anatomy.knees_forward(swung)
    assert not anatomy.knees_backwards(fixed).any()
    grot_f, gpos_f = K.fk(fixed.lrot, fixed.lpos, fixed.skeleton.parents)
    feet = [C.INDEX[n] for n in ("Foot_L", "Toes_L", "Foot_R", "Toes_R")]
    assert np.abs(gpos_f[:, feet] - gpos[:, feet]).max() < 1e-6 * H
    assert np.abs(np.abs(np.einsum("fji,fji->fj", grot_f[:, feet], grot[:, feet])) - 1).max() < 1e-9
    np.testing.assert_array_equal(fixed.lrot[:, knee], walk.lrot[:, knee])  # the bend stays
    untouched = np.ones(walk.num_frames, dtype=bool)
    untouched[40 - 20 : 50 + 20] = False  # the swivel fades in and out over 0.2 s (+ tails)
    np.testing.assert_array_equal(fixed.lrot[untouched], walk.lrot[untouched])
    assert anatomy.knees_forward(walk) is not walk  # a new motion, the same poses
    np.testing.assert_array_equal(anatomy.knees_forward(walk).lrot, walk.lrot)


def test_an_elbow_bent_the_wrong_way_is_seen_and_a_flexed_one_is_not(bandai):
    def elbows_at(degrees: float):
        lrot = bandai.lrot.copy()
        for joint, child, axis, bend in anatomy.HINGES:
            if joint in anatomy.ELBOWS:
                rest = C.OFFSETS[C.INDEX[child]]
                sense = np.sign(np.dot(np.cross(axis, rest), bend))  # turns rest toward bend
                lrot[:, C.INDEX[joint]] = R.from_rotvec(axis * sense * np.radians(degrees))
        return bandai.replace(lrot=lrot)

    assert not anatomy.elbows_backwards(bandai).any()
    assert not anatomy.elbows_backwards(elbows_at(60.0)).any()  # flexed
    assert anatomy.elbows_backwards(elbows_at(-60.0)).all()  # bent back
    assert not anatomy.elbows_backwards(anatomy.hinged(elbows_at(-60.0))).any()


def with_upper_arm_twist_flip(motion, at: int):
    """``motion`` with its left elbow flexed 90 degrees and, from frame ``at`` on, its upper
    arm turned 150 degrees about its own axis: the hand swings round in one frame."""
    lrot = motion.lrot.copy()
    lrot[:, C.INDEX["LowerArm_L"]] = R.from_rotvec(np.array([0.0, np.pi / 2, 0.0]))
    bone = C.OFFSETS[C.INDEX["LowerArm_L"]] / np.linalg.norm(C.OFFSETS[C.INDEX["LowerArm_L"]])
    j = C.INDEX["UpperArm_L"]
    lrot[at:, j] = R.mul(lrot[at:, j], R.from_rotvec(bone * np.radians(150.0)))
    return motion.replace(lrot=lrot)


def test_a_twist_flip_is_bridged_and_the_rest_left_bit_for_bit(bandai):
    flexed = with_upper_arm_twist_flip(bandai, at=bandai.num_frames)  # no flip
    flipped = with_upper_arm_twist_flip(bandai, at=60)
    assert anatomy.peak_speed(flipped) > anatomy.SPEED_LIMIT + 2.0
    fixed = anatomy.despiked(flipped, bandai)
    assert anatomy.peak_speed(fixed) <= anatomy.SPEED_LIMIT
    changed = np.flatnonzero((fixed.lrot != flipped.lrot).any(axis=(1, 2)))
    assert 59 - anatomy.SPIKE_REACH <= changed.min() and changed.max() <= 60 + anatomy.SPIKE_REACH
    assert anatomy.despiked(flexed, bandai) is flexed  # nothing faster than allowed


def test_content_that_is_fast_itself_is_left_as_fast(bandai):
    fast = time_warp(bandai, 2.5 * anatomy.SPEED_LIMIT / anatomy.peak_speed(bandai))
    assert anatomy.peak_speed(fast) > 2 * anatomy.SPEED_LIMIT
    assert anatomy.despiked(fast, fast) is fast


def test_the_warp_plays_no_faster_than_real_mocap_and_keeps_both_ends(bandai):
    peak = anatomy.peak_speed(bandai)
    assert 0.5 < peak < anatomy.SPEED_LIMIT  # a walk: about a body height a second
    even = anatomy.speed_limited_warp(1.2, bandai)
    assert even == anatomy.Warp(1.2)  # within the limit: the even warp, as before
    assert even.apply(bandai).num_frames == time_warp(bandai, 1.2).num_frames
    limited = anatomy.speed_limited_warp(100.0, bandai)
    warped = limited.apply(bandai)
    assert anatomy.peak_speed(warped) <= anatomy.SPEED_LIMIT * 1.02
    assert limited.factor < anatomy.SPEED_LIMIT / peak * 2  # slowed where the walk is fastest
    np.testing.assert_allclose(warped.lrot[[0, -1]], bandai.lrot[[0, -1]])
    assert anatomy.speed_limited_warp(0.7, bandai) == anatomy.Warp(0.7)


def test_content_faster_than_real_mocap_is_slowed_only_where_it_is(bandai):
    fast = time_warp(bandai, 2.0 * anatomy.SPEED_LIMIT / anatomy.peak_speed(bandai))
    fastest = anatomy.joint_speeds(fast).max(axis=1)
    assert fastest.max() > 1.5 * anatomy.SPEED_LIMIT and (fastest < anatomy.SPEED_LIMIT).any()
    warp = anatomy.speed_limited_warp(1.0, fast)
    assert warp.factor < 1.0  # slowed below its own timing, where it is too fast
    warped = warp.apply(fast)
    assert anatomy.peak_speed(warped) <= anatomy.SPEED_LIMIT * 1.02
    # each step's rate: 1 where every joint is slow enough, less where one is not
    rates = np.diff(warp.source) / np.diff(warp.played) * warp.factor
    assert rates.max() == pytest.approx(1.0) and rates.min() < 0.6


# --- root motion ---------------------------------------------------------------------------


@pytest.mark.parametrize("upright", [True, False], ids=["y-up", "z-up"])
def test_in_place_removes_travel_and_keeps_bob_and_facing(upright):
    motion = rigs.load_fixture() if upright else rigs.z_up(rigs.load_fixture())
    rig = retarget.make_rig(motion.skeleton, motion)
    hips = rig.mapping["Hips"]
    still = root_motion.in_place(motion, hips, rig.up)
    before = R.apply(rig.up, K.global_positions(motion)[:, hips])
    after = R.apply(rig.up, K.global_positions(still)[:, hips])
    assert np.ptp(before[:, [0, 2]], axis=0).max() > 0.5 * rig.height  # it walked
    assert np.ptp(after[:, [0, 2]], axis=0).max() < 1e-9 * rig.height
    assert np.allclose(after[:, 1], before[:, 1])
    assert np.allclose(still.lrot, motion.lrot)


def test_a_stretch_taken_as_a_loop_runs_on_into_its_first_frame():
    take = canonical(rigs.load_fixture().slice(0, 90))
    loop = loops.detect(take, force=True)
    assert loop is not None and loop.gap > loops.OPEN_GAP  # its ends do not meet
    cycle = loops.closed(take, loop)
    local = loops.local_poses(cycle)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    assert steps[-1] < 1.25 * steps[-2]  # into the closing frame as its last step went
    jump, _ = loops.loop_jump(cycle)
    assert jump < 1e-9 * H
    assert (
        np.abs(K.global_positions(cycle.slice(0, 1)) - K.global_positions(take.slice(0, 1))).max()
        < 1e-9
    )


def test_any_rig_gains_its_first_frame_one_step_on():
    walk = rigs.z_up(rigs.load_fixture().slice(0, 30))
    rig = retarget.make_rig(walk.skeleton, walk)
    longer = loops.with_closing_frame(walk, rig.up)
    assert longer.num_frames == 31 and np.allclose(longer.lrot[-1], walk.lrot[0])
    root = R.apply(rig.up, longer.lpos[:, 0])
    assert np.allclose(root[-1, [0, 2]], 2 * root[-2, [0, 2]] - root[-3, [0, 2]])
    assert root[-1, 1] == pytest.approx(root[0, 1])

"""Foot contacts, foot skating, two-bone IK, foot pinning and fitting rotations to positions
(the clean-up of canonical motions built on them: test_grounding.py)."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh, fit, grounding, ik, retarget
from motion import canonical as C
from motion import contacts as CT
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion
from tests.conftest import data_path

WALK = ("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh")
CMU_WALK = ("cmu-31", "07_01.bvh")
CMU_FEET = ["LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"]


@pytest.fixture(scope="module")
def walk() -> Motion:
    return retarget.to_canonical(bvh.load(data_path(*WALK)))


@pytest.fixture(scope="module")
def cmu_walk() -> Motion:
    return bvh.load(data_path(*CMU_WALK)).slice(1)  # frame 0 is cgspeed's T-pose


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True))


def _bone_lengths(gpos: np.ndarray, parents: np.ndarray) -> np.ndarray:
    return np.linalg.norm(gpos[:, 1:] - gpos[:, parents[1:]], axis=-1)


def _cmu_legs(skeleton) -> list[tuple[int, int, int, int]]:
    return [
        tuple(skeleton.index(f"{side}{part}") for part in ("UpLeg", "Leg", "Foot", "ToeBase"))
        for side in ("Left", "Right")
    ]


def _knee_bend_degrees(motion: Motion) -> np.ndarray:
    """Signed knee bend ``(F, 2)`` of a canonical motion about the thigh's hinge (+X):
    positive when the knee is in front."""
    grot, gpos = K.fk(motion.lrot, motion.lpos, C.PARENTS)
    out = []
    for hip, knee, ankle in [(14, 15, 16), (18, 19, 20)]:
        thigh = gpos[:, knee] - gpos[:, hip]
        shin = gpos[:, ankle] - gpos[:, knee]
        hinge = rot.apply(grot[:, hip], np.array([1.0, 0.0, 0.0]))
        sine = np.sum(np.cross(thigh, shin) * hinge, axis=-1)
        sine /= np.linalg.norm(thigh, axis=-1) * np.linalg.norm(shin, axis=-1)
        out.append(np.degrees(np.arcsin(np.clip(sine, -1.0, 1.0))))
    return np.stack(out, axis=1)


def _swayed(motion: Motion) -> Motion:
    """The motion with a sinusoidal sway of the hips (a few cm, ~1 Hz)."""
    t = np.arange(motion.num_frames) / motion.fps
    lpos = motion.lpos.copy()
    lpos[:, 1, 0] += 4.0 * np.sin(2 * np.pi * 1.3 * t)
    lpos[:, 1, 2] += 3.0 * np.sin(2 * np.pi * 0.9 * t + 1.0)
    lpos[:, 1, 1] += 1.5 * np.sin(2 * np.pi * 2.1 * t)
    return motion.replace(lpos=lpos)


def test_walk_contacts_are_plausible_and_alternate(walk):
    contacts = CT.canonical_foot_contacts(walk)
    assert contacts.shape == (walk.num_frames, 4) and contacts.dtype == bool
    feet = contacts[:, [0, 2]] | contacts[:, [1, 3]]  # a foot touches by heel or toe
    assert np.all((feet.mean(axis=0) > 0.3) & (feet.mean(axis=0) < 0.8))
    assert (~feet.any(axis=1)).mean() < 0.2  # a walk is rarely airborne
    left, right = (_runs(feet[:, i]) for i in range(2))
    assert len(left) >= 3 and len(right) >= 3
    # steps alternate: between two left contacts the right foot lands
    right_starts = np.array([start for start, _ in right])
    for (_, stop), (start, _) in zip(left[:-1], left[1:], strict=True):
        assert np.any((right_starts >= stop - 2) & (right_starts <= start + 2))


def test_contacts_do_not_depend_on_units_or_floor_height(cmu_walk):
    sk = cmu_walk.skeleton
    feet = [sk.index(n) for n in CMU_FEET]
    gpos = K.global_positions(cmu_walk)
    leg = CT.chain_length(sk, sk.index("LeftUpLeg"), sk.index("LeftFoot"))
    labels = CT.foot_contacts(gpos, cmu_walk.fps, feet, scale=leg)
    assert 0.2 < labels.mean() < 0.8
    big = Motion(sk.with_offsets(sk.offsets * 10), cmu_walk.fps, cmu_walk.lrot, cmu_walk.lpos * 10)
    big_gpos = K.global_positions(big)
    np.testing.assert_array_equal(CT.foot_contacts(big_gpos, big.fps, feet, scale=leg * 10), labels)
    # the estimated scale scales too
    np.testing.assert_array_equal(
        CT.foot_contacts(big_gpos, big.fps, feet), CT.foot_contacts(gpos, cmu_walk.fps, feet)
    )
    raised = gpos + np.array([0.0, 7.0, 0.0])
    np.testing.assert_array_equal(CT.foot_contacts(raised, cmu_walk.fps, feet, scale=leg), labels)


def test_contact_flicker_is_removed():
    raw = np.array([0, 1, 0, 0, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 1], dtype=bool)[:, None]
    cleaned = CT.clean_contacts(raw, 2)
    expected = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1, 1], dtype=bool)[:, None]
    np.testing.assert_array_equal(cleaned, expected)


def test_foot_skating_measures_sliding_speed():
    frames, fps = 20, 30.0
    gpos = np.zeros((frames, 2, 3))
    gpos[:, 1, 0] = np.arange(frames) * 0.5  # 15 units per second along X
    gpos[:, 1, 1] = np.arange(frames) * 0.2  # vertical motion does not count
    contacts = np.zeros((frames, 1), dtype=bool)
    assert CT.foot_skating(gpos, contacts, fps, [1]) == 0.0
    contacts[5:15] = True
    assert CT.foot_skating(gpos, contacts, fps, [1]) == pytest.approx(15.0)
    assert CT.foot_skating(gpos, contacts, fps, [1], leg_length=3.0) == pytest.approx(5.0)
    with pytest.raises(MotionError):
        CT.foot_skating(gpos, contacts[:, [0, 0]], fps, [1])


def test_foot_sliding_weighs_speed_by_closeness_to_the_ground():
    frames, fps = 40, 30.0
    gpos = np.zeros((frames, 2, 3))
    gpos[:, 1, 0] = np.arange(frames) * 0.5  # 15 units per second along X, on the floor
    assert CT.foot_sliding(gpos, fps, [1], height=2.0, scale=1.0) == pytest.approx(15.0)
    lifted = gpos.copy()
    lifted[20:, 1, 1] = 1.0  # half the time 1 unit up: weight 2 - 2 ** 0.5
    expected = 15.0 * (20 + 20 * (2 - 2**0.5)) / 40
    assert CT.foot_sliding(lifted, fps, [1], height=2.0, scale=1.0) == pytest.approx(expected)
    lifted[20:, 1, 1] = 5.0  # above the threshold: not counted
    assert CT.foot_sliding(lifted, fps, [1], height=2.0, scale=1.0) == pytest.approx(7.5, rel=0.05)
    planted = np.zeros_like(gpos)
    assert CT.foot_sliding(planted, fps, [1], height=2.0, scale=1.0) == 0.0
    with pytest.raises(MotionError):
        CT.foot_sliding(gpos[..., :2], fps, [1], height=2.0)


def test_foot_skating_on_real_data_is_small(walk, cmu_walk):
    skate = CT.canonical_foot_skating(walk)
    assert 0.0 < skate < 0.1 * C.leg_length()  # cm/s, well under 0.1 leg lengths a second
    sk = cmu_walk.skeleton
    feet = [sk.index(n) for n in CMU_FEET]
    gpos = K.global_positions(cmu_walk)
    leg = CT.chain_length(sk, sk.index("LeftUpLeg"), sk.index("LeftFoot"))
    labels = CT.foot_contacts(gpos, cmu_walk.fps, feet, scale=leg)
    assert CT.foot_skating(gpos, labels, cmu_walk.fps, feet, leg_length=leg) < 0.25
    # sliding needs no labels: a real walk's feet move far slower near the floor than overall
    feet = K.global_positions(walk)[:, list(CT.CANONICAL_FOOT_JOINTS)]
    overall = CT.horizontal_speed(feet, walk.fps).mean()
    assert 0.0 < CT.canonical_foot_sliding(walk) < 0.3 * overall


def _random_legs(rng, count):
    hip = rng.normal(size=(count, 3))
    knee = hip + rng.normal(size=(count, 3))
    ankle = knee + rng.normal(size=(count, 3))
    return hip, knee, ankle


def test_two_bone_ik_reaches_reachable_targets_keeping_lengths():
    rng = np.random.default_rng(1)
    hip, knee, ankle = _random_legs(rng, 5000)
    thigh = np.linalg.norm(knee - hip, axis=-1)
    shin = np.linalg.norm(ankle - knee, axis=-1)
    dist = rng.uniform(np.abs(thigh - shin) + 0.01 * (thigh + shin), 0.99 * (thigh + shin))
    direction = rng.normal(size=(5000, 3))
    target = hip + dist[:, None] * direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    leg = ik.two_bone_ik(hip, knee, ankle, target)
    assert np.abs(leg.ankle - target).max() < 1e-6
    np.testing.assert_allclose(np.linalg.norm(leg.knee - hip, axis=-1), thigh, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(leg.ankle - leg.knee, axis=-1), shin, rtol=1e-9)
    # the rotations say the same as the positions
    np.testing.assert_allclose(hip + rot.apply(leg.hip_turn, knee - hip), leg.knee, atol=1e-9)
    # an unmoved target leaves the leg where it is
    same = ik.two_bone_ik(hip, knee, ankle, ankle)
    bent = np.linalg.norm(np.cross(knee - hip, ankle - knee), axis=-1) > 1e-2 * thigh * shin
    assert np.abs(same.knee - knee)[bent].max() < 1e-6


def test_two_bone_ik_clamps_unreachable_targets_without_nan():
    rng = np.random.default_rng(2)
    hip, knee, ankle = _random_legs(rng, 1000)
    full = np.linalg.norm(knee - hip, axis=-1) + np.linalg.norm(ankle - knee, axis=-1)
    direction = rng.normal(size=(1000, 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    beyond = hip + 3.0 * full[:, None] * direction
    for target in (beyond, hip, hip + 1e-9):
        leg = ik.two_bone_ik(hip, knee, ankle, target, eps=1e-3)
        assert np.all(np.isfinite(leg.knee)) and np.all(np.isfinite(leg.ankle))
        assert np.all(np.isfinite(leg.hip_turn)) and np.all(np.isfinite(leg.knee_turn))
    far = ik.two_bone_ik(hip, knee, ankle, beyond, eps=1e-3)
    reach = np.linalg.norm(far.ankle - hip, axis=-1)
    # straightened to 1 - eps of full length (or kept as straight as it was), towards the target
    now = np.linalg.norm(ankle - hip, axis=-1)
    np.testing.assert_allclose(reach, np.maximum(full * (1 - 1e-3), now), rtol=1e-9)
    np.testing.assert_allclose((far.ankle - hip) / reach[:, None], direction, atol=1e-9)


def test_two_bone_ik_keeps_the_knee_side_and_follows_the_pole():
    hip = np.array([0.0, 90.0, 0.0])
    knee = np.array([0.0, 50.0, 5.0])  # bent forward (+Z)
    ankle = np.array([0.0, 10.0, 0.0])
    for target in ([0.0, 20.0, 0.0], [0.0, 12.0, 8.0], [5.0, 10.0, -10.0], [0.0, 0.0, 0.0]):
        leg = ik.two_bone_ik(hip, knee, ankle, np.array(target))
        line = leg.ankle - hip
        forward = leg.knee - hip - np.dot(leg.knee - hip, line) / np.dot(line, line) * line
        assert forward[2] > 0  # still in front
    straight = ik.two_bone_ik(
        np.zeros(3), np.array([0.0, -1.0, 0.0]), np.array([0.0, -2.0, 0.0]),
        np.array([0.0, -1.5, 0.0]), pole=np.array([0.0, 0.0, 1.0]),
    )  # fmt: skip
    assert straight.knee[2] > 0.5
    np.testing.assert_allclose(straight.ankle, [0.0, -1.5, 0.0], atol=1e-12)


def _check_pinned(before: Motion, after: Motion, legs) -> None:
    """Bone lengths exact, ankle rotations kept, nothing but the legs moved, no pops."""
    parents = before.skeleton.parents
    grot0, gpos0 = K.fk(before.lrot, before.lpos, parents)
    grot1, gpos1 = K.fk(after.lrot, after.lpos, parents)
    np.testing.assert_allclose(
        _bone_lengths(gpos1, parents), _bone_lengths(gpos0, parents), rtol=1e-6, atol=1e-9
    )
    for _, _, ankle, _ in legs:
        assert rot.angle(rot.mul(rot.inv(grot0[:, ankle]), grot1[:, ankle])).max() < 1e-9
    leg_joints = {j for leg in legs for j in leg}
    others = [j for j in range(len(parents)) if j not in leg_joints]
    np.testing.assert_allclose(gpos1[:, others], gpos0[:, others], atol=1e-9)
    # smooth: accelerations of the leg stay of the order of the input's
    moved = [j for leg in legs for j in leg[1:]]
    scale = max(np.abs(np.diff(gpos0[:, moved], 2, axis=0)).max(), 1e-9)
    assert np.abs(np.diff(gpos1[:, moved], 2, axis=0)).max() < 2.0 * scale
    assert np.all(np.isfinite(after.lrot))


def test_pin_feet_reduces_skating_on_a_real_walk(walk):
    contacts = CT.canonical_foot_contacts(walk)
    lrot_before = walk.lrot.copy()
    pinned = grounding.pin_canonical_feet(walk, contacts, hold_flat_feet=False)
    np.testing.assert_array_equal(walk.lrot, lrot_before)  # input left alone
    before = CT.canonical_foot_skating(walk, contacts)
    after = CT.canonical_foot_skating(pinned, contacts)
    assert after < 0.5 * before
    # the ankles themselves hold still while they touch
    gpos = K.global_positions(pinned)
    ankles = [C.INDEX["Foot_L"], C.INDEX["Foot_R"]]
    ankle_only = contacts[:, [0, 2]] & ~contacts[:, [1, 3]]
    assert CT.foot_skating(gpos, ankle_only, walk.fps, ankles) < 0.05
    _check_pinned(walk, pinned, grounding.CANONICAL_LEGS)
    assert _knee_bend_degrees(pinned).min() > -1.0  # the knee never bends backwards


def test_pin_feet_removes_hip_sway_skating(walk):
    contacts = CT.canonical_foot_contacts(walk)  # labels of the clean clip
    swayed = _swayed(walk)
    pinned = grounding.pin_canonical_feet(swayed, contacts, hold_flat_feet=False)
    before = CT.canonical_foot_skating(swayed, contacts)
    after = CT.canonical_foot_skating(pinned, contacts)
    assert before > 3.0 * CT.canonical_foot_skating(walk, contacts)
    assert after < 0.15 * before
    _check_pinned(swayed, pinned, grounding.CANONICAL_LEGS)
    bend_before = _knee_bend_degrees(swayed)
    bend_after = _knee_bend_degrees(pinned)
    assert bend_after.min() > -1.0
    clearly_bent = np.abs(bend_before) > 5.0
    assert np.all(np.sign(bend_after[clearly_bent]) == np.sign(bend_before[clearly_bent]))


def _wobbly_feet(motion: Motion) -> Motion:
    """The motion with its feet turning about (~8 degrees, 1-3 Hz), as a decoder's are."""
    t = np.arange(motion.num_frames)[:, None] / motion.fps
    lrot = motion.lrot.copy()
    for k, joint in enumerate(("Foot_L", "Foot_R")):
        wobble = np.concatenate(
            [0.14 * np.sin(2 * np.pi * (1.1 + k) * t), 0.1 * np.sin(2 * np.pi * 2.7 * t + k),
             0.12 * np.sin(2 * np.pi * 1.7 * t + 2 * k)], axis=1,
        )  # fmt: skip
        j = C.INDEX[joint]
        lrot[:, j] = rot.mul(lrot[:, j], rot.from_rotvec(wobble))
    return motion.replace(lrot=lrot)


def test_flat_feet_are_held_in_one_orientation(walk):
    contacts = CT.canonical_foot_contacts(walk)
    wobbly = _wobbly_feet(walk)
    held = grounding.pin_canonical_feet(wobbly, contacts)
    kept = grounding.pin_canonical_feet(wobbly, contacts, hold_flat_feet=False)
    flat = contacts[:, [0, 2]] & contacts[:, [1, 3]]
    feet = [C.INDEX[n] for n in ("Foot_L", "Foot_R")]
    toes = [C.INDEX[n] for n in ("Toes_L", "Toes_R")]

    def sliding(motion, joints):  # cm/s of the joints while their foot is flat
        return CT.foot_skating(K.global_positions(motion), flat, walk.fps, joints)

    # holding one point of a turning foot slides the rest of it; holding its
    # orientation too keeps heel and toe still
    assert sliding(kept, toes) > 3 * sliding(held, toes)
    assert sliding(held, feet) < 0.5 and sliding(held, toes) < 0.5
    # off the ground the feet keep their own rotation
    grot0, _ = K.fk(wobbly.lrot, wobbly.lpos, C.PARENTS)
    grot1, gpos1 = K.fk(held.lrot, held.lpos, C.PARENTS)
    blend = int(round(ik.BLEND_SECONDS * walk.fps))
    near = np.zeros_like(flat)
    for i in range(2):
        for start, stop in _runs(flat[:, i]):
            near[max(start - blend - 1, 0) : stop + blend + 1, i] = True
    for i, foot in enumerate(feet):
        turn = rot.angle(rot.mul(rot.inv(grot0[:, foot]), grot1[:, foot]))
        assert turn[~near[:, i]].max() < 1e-9
    bones = _bone_lengths(gpos1, C.PARENTS)
    np.testing.assert_allclose(
        bones, _bone_lengths(K.global_positions(wobbly), C.PARENTS), rtol=1e-6
    )


def test_pin_feet_works_on_another_skeleton(cmu_walk):
    sk = cmu_walk.skeleton
    feet = [sk.index(n) for n in CMU_FEET]
    leg = CT.chain_length(sk, sk.index("LeftUpLeg"), sk.index("LeftFoot"))
    gpos = K.global_positions(cmu_walk)
    contacts = CT.foot_contacts(gpos, cmu_walk.fps, feet, scale=leg)
    legs = _cmu_legs(sk)
    pinned = ik.pin_feet(cmu_walk, contacts[:, [0, 2]], legs, toe_contacts=contacts[:, [1, 3]])
    before = CT.foot_skating(gpos, contacts, cmu_walk.fps, feet)
    after = CT.foot_skating(K.global_positions(pinned), contacts, cmu_walk.fps, feet)
    assert after < 0.4 * before
    _check_pinned(cmu_walk, pinned, legs)
    # ankle contacts alone (no toes): the ankles hold still
    heel_only = ik.pin_feet(cmu_walk, contacts[:, [0, 2]], [(*leg[:3], None) for leg in legs])
    after_ankle = CT.foot_skating(
        K.global_positions(heel_only), contacts[:, [0, 2]], cmu_walk.fps, feet[::2]
    )
    assert after_ankle < 1e-3 * leg


def test_pin_feet_bends_straight_legs_forward():
    """T-pose legs (never bent in the clip) under a pelvis that dips: the knees bend
    forward, towards the toes, and the feet stay down."""
    frames = 100
    lrot = rot.identity((frames, len(C.JOINTS)))
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    t = np.arange(frames)
    dip = np.where(np.abs(t - 50) < 3, 10.0 * np.cos((t - 50) / 3 * np.pi / 2) ** 2, 0.0)
    lpos[:, 1, 1] -= dip
    standing = Motion(C.SKELETON, C.FPS, lrot, lpos)
    pinned = grounding.pin_canonical_feet(standing, np.ones((frames, 4), dtype=bool))
    bend = _knee_bend_degrees(pinned)
    assert bend.min() > -1e-6 and bend[50].min() > 30.0
    ankles = K.global_positions(pinned)[:, [C.INDEX["Foot_L"], C.INDEX["Foot_R"]]]
    assert np.ptp(ankles, axis=0).max() < 0.5  # cm
    _check_pinned(standing, pinned, grounding.CANONICAL_LEGS)


def test_pin_feet_without_contacts_changes_nothing(walk):
    none = np.zeros((walk.num_frames, 4), dtype=bool)
    out = grounding.pin_canonical_feet(walk, none)
    np.testing.assert_array_equal(out.lrot, walk.lrot)
    with pytest.raises(MotionError):
        grounding.pin_canonical_feet(walk, none[:, :3])


@pytest.mark.parametrize("bones", [2, 3, 6])
def test_best_rotation_of_several_bones_matches_scipy(bones):
    """fit's closed-form best rotation against scipy's ``align_vectors``, frame by frame:
    noisy and mirrored targets (where the best reflection is not a rotation) alike."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(bones)
    a = rng.normal(size=(40, bones, 3))
    turn = rot.normalize(rng.normal(size=(40, 4)))
    b = rot.apply(turn[:, None], a) + rng.normal(0.0, 0.3, a.shape)
    b[20:] *= np.array([-1.0, 1.0, 1.0])  # mirrored
    q, ok = fit._kabsch(a, b)
    assert ok.all()
    for f in range(len(a)):
        expected = Rotation.align_vectors(b[f], a[f])[0].as_quat()
        assert min(np.abs(q[f] - expected).max(), np.abs(q[f] + expected).max()) < 1e-7
    line = np.repeat(rng.normal(size=(5, 1, 3)), bones, axis=1) * np.arange(1, bones + 1)[:, None]
    q, ok = fit._kabsch(line, line + 0.5)
    assert not ok.any() and np.isfinite(q).all()
    q, ok = fit._kabsch(np.zeros((3, bones, 3)), np.zeros((3, bones, 3)))
    np.testing.assert_array_equal(q, rot.identity((3,)))


def test_fit_positions_recovers_a_real_motion(walk):
    gpos = K.global_positions(walk)
    height = C.SKELETON.height()
    free = fit.fit_positions(gpos, C.SKELETON, fps=walk.fps)
    assert free.fps == walk.fps
    assert np.abs(K.global_positions(free) - gpos).max() < 1e-6 * height
    # pelvis and chest are fixed by their several bones, twist and all
    grot, grot_free = K.global_rotations(walk), K.global_rotations(free)
    for name in ("Hips", "Chest"):
        j = C.INDEX[name]
        assert rot.angle(rot.mul(rot.inv(grot[:, j]), grot_free[:, j])).max() < 1e-6


def test_fit_positions_on_noisy_targets_keeps_bones_rigid(walk):
    gpos = K.global_positions(walk)
    noisy = gpos + np.random.default_rng(3).normal(scale=1.0, size=gpos.shape)  # 1 cm
    target_before = noisy.copy()
    fitted = fit.fit_positions(noisy, C.SKELETON)
    np.testing.assert_array_equal(noisy, target_before)
    fit_gpos = K.global_positions(fitted)
    lengths = np.linalg.norm(C.OFFSETS[2:], axis=-1)  # every bone below the hips
    np.testing.assert_allclose(_bone_lengths(fit_gpos, C.PARENTS)[:, 1:], lengths[None].repeat(
        len(gpos), 0), rtol=1e-6)  # fmt: skip
    error = np.linalg.norm(fit_gpos - gpos, axis=-1)
    assert np.sqrt(np.mean(error**2)) < 2.0  # about the noise (sqrt(3) cm), no worse


def test_fit_positions_on_a_skeleton_with_zero_length_bones(cmu_walk):
    gpos = K.global_positions(cmu_walk)
    fitted = fit.fit_positions(gpos, cmu_walk.skeleton, fps=cmu_walk.fps)
    assert np.abs(K.global_positions(fitted) - gpos).max() < 1e-6 * cmu_walk.skeleton.height()
    with pytest.raises(MotionError):
        fit.fit_positions(gpos[:, :-1], cmu_walk.skeleton)

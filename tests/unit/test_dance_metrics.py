"""The dance-generation papers' measures (training.dance_metrics) on canonical motion."""

from __future__ import annotations

import numpy as np
import pytest

from motion import canonical as C
from motion import rotations as R
from motion.skeleton import Motion
from training import dance_metrics as DM

FPS = 30.0


def standing(frames: int, hips_path: np.ndarray | None = None) -> Motion:
    """The canonical T-pose for ``frames`` frames, the hips moved along ``hips_path``."""
    lrot = R.identity((frames, len(C.JOINTS)))
    lpos = np.repeat(C.SKELETON.offsets[None], frames, axis=0)
    if hips_path is not None:
        lpos[:, C.INDEX["Hips"]] += hips_path
    return Motion(C.SKELETON, FPS, lrot, lpos)


def bent(motion: Motion, joint: str, degrees: np.ndarray, axis=(0.0, 0.0, 1.0)) -> Motion:
    lrot = motion.lrot.copy()
    lrot[:, C.INDEX[joint]] = R.from_rotvec(np.radians(degrees)[:, None] * np.asarray(axis))
    return motion.replace(lrot=lrot)


def test_kinetic_features_are_the_squared_speeds_and_the_acceleration():
    frames = 60
    still = DM.kinetic_features(DM.body_positions(standing(frames)), FPS)
    assert still.shape == (63,) and np.allclose(still, 0.0)
    # the whole body glides sideways at 0.6 m/s and rises at 0.3 m/s
    path = np.arange(frames)[:, None] / FPS * np.array([60.0, 30.0, 0.0])
    gliding = DM.kinetic_features(DM.body_positions(standing(frames, path)), FPS).reshape(21, 3)
    assert np.allclose(gliding[:, 0], 0.36) and np.allclose(gliding[:, 1], 0.09)
    assert np.allclose(gliding[:, 2], 0.0, atol=1e-9)
    # falling freely from rest: the acceleration is g wherever the window is whole
    t = np.arange(frames) / FPS
    fall = np.stack([0 * t, -0.5 * 981.0 * t**2, 0 * t], axis=1)
    falling = DM.kinetic_features(DM.body_positions(standing(frames, fall)), FPS).reshape(21, 3)
    assert np.allclose(falling[:, 2], 9.81, rtol=1e-6)


def test_geometric_features_read_the_pose():
    frames = 30
    t_pose = DM.geometric_features(DM.body_positions(standing(frames)), FPS)
    assert t_pose.shape == (32,) and set(np.unique(t_pose)) <= {0.0, 1.0}
    # straight elbows and knees, the trunk not lying, arms away from it and the hands wide
    # apart, nothing fast
    assert t_pose[6] == t_pose[7] == t_pose[19] == t_pose[20] == t_pose[28] == 0.0
    assert t_pose[8] == t_pose[23] == t_pose[24] == 1.0
    assert t_pose[12] == t_pose[13] == t_pose[31] == 0.0
    # the left elbow bent by 90 degrees in half of the frames
    half = np.where(np.arange(frames) < frames // 2, 0.0, 90.0)
    elbow = DM.geometric_features(
        DM.body_positions(bent(standing(frames), "LowerArm_L", half)), FPS
    )
    assert elbow[7] == pytest.approx(15 / 29) and elbow[6] == 0.0
    # the right hand raised over the head: the arm rotated 90 degrees up
    raised = bent(standing(frames), "UpperArm_R", np.full(frames, -90.0))
    up = DM.geometric_features(DM.body_positions(raised), FPS)
    assert up[2] == 1.0 and up[3] == 0.0


def test_frechet_distance_of_gaussians():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(4000, 3))
    assert DM.frechet_distance(a, a) == pytest.approx(0.0, abs=1e-6)
    # N(0, 1) against N(2, 3^2) per dimension: 2^2 + (3 - 1)^2 = 8 each
    b = 2.0 + 3.0 * rng.normal(size=(4000, 3))
    assert DM.frechet_distance(a, b) == pytest.approx(24.0, rel=0.05)
    assert DM.frechet_distance(a, b) == pytest.approx(DM.frechet_distance(b, a), rel=1e-6)
    with pytest.raises(ValueError, match="two feature vectors"):
        DM.frechet_distance(a[:1], b)


def test_frechet_terms_split_location_from_spread():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(4000, 3))
    # N(0, 1) against N(2, 3^2) per dimension: 2^2 where they lie, (3 - 1)^2 how they spread
    location, spread = DM.frechet_terms(a, 2.0 + 3.0 * rng.normal(size=(4000, 3)))
    assert location == pytest.approx(12.0, rel=0.05) and spread == pytest.approx(12.0, rel=0.05)
    # pieces that all look alike: the same mean, half the spread -> (1 - 0.5)^2 per dimension
    location, spread = DM.frechet_terms(a, 0.5 * rng.normal(size=(4000, 3)))
    assert location < 0.01 and spread == pytest.approx(0.75, rel=0.1)
    size, draws = 50, 30
    terms = DM.matched_frechet_terms(a, a[:200], size, draws=draws)
    assert sum(terms) == pytest.approx(DM.matched_frechet(a, a[:200], size, draws=draws))


def test_matched_frechet_compares_at_one_size():
    rng = np.random.default_rng(1)
    reference, many = rng.normal(size=(10, 2)), rng.normal(size=(400, 2))
    # few samples of the same distribution lie further than many; matched, they agree
    few = many[:10]
    assert DM.frechet_distance(many, reference) < DM.frechet_distance(few, reference)
    matched = DM.matched_frechet(many, reference, 10, draws=200)
    assert abs(matched - DM.frechet_distance(few, reference)) < 0.5 * matched


def test_diversity_and_normaliser():
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    assert DM.diversity(triangle) == pytest.approx(1.0)
    norm = DM.Normaliser(np.array([[1.0, 10.0], [3.0, 10.0]]))
    assert np.allclose(norm(np.array([[3.0, 10.0]])), [[1.0, 0.0]])
    # a feature constant in the reference is centred, not blown up by a zero std
    assert np.allclose(norm(np.array([[3.0, 10.03]])), [[1.0, 0.03]])


def test_foot_contact_score_punishes_a_body_pushed_with_no_foot_planted():
    frames = 150
    t = np.arange(frames) / FPS
    sway = np.stack([20.0 * np.sin(2 * np.pi * t), 0 * t, 0 * t], axis=1)
    # the whole body sways, feet included: neither foot is planted
    floating = standing(frames, sway)
    assert DM.physical_foot_contact(floating) > 1.0
    # the same hips, the feet kept where they were: the legs push it
    planted = floating.replace(lpos=floating.lpos.copy())
    for leg in ("UpperLeg_L", "UpperLeg_R"):
        planted.lpos[:, C.INDEX[leg]] -= sway
    assert DM.physical_foot_contact(planted) == pytest.approx(0.0, abs=1e-9)
    assert DM.physical_foot_contact(standing(frames)) == 0.0


def test_feature_distances_of_a_copy_of_the_real_dance_are_nil():
    from training.dance_metrics import feature_distances

    frames = 600
    t = np.arange(frames) / FPS
    real = bent(standing(frames), "LowerArm_L", 60 + 50 * np.sin(2 * np.pi * 0.7 * t))
    real = bent(real, "LowerLeg_R", 30 + 30 * np.sin(2 * np.pi * 1.3 * t), axis=(1.0, 0, 0))
    other = bent(standing(frames), "LowerArm_R", 40 + 40 * np.sin(2 * np.pi * 1.1 * t))
    other = bent(other, "LowerLeg_L", 20 + 20 * np.sin(2 * np.pi * 0.9 * t), axis=(1.0, 0, 0))
    held = [("song", "waltz", real, None, None)]
    report = feature_distances(held, [("waltz", other)], {"song": [real]})
    for half in ("dev", "test"):
        row = report[half]["waltz"]
        assert row["pieces"] == {"real": 2, "generated": 2, "other_songs": 4}
        for kind in DM.FEATURES:
            assert row[kind]["generated_to_real"] == pytest.approx(0.0, abs=0.01)
            assert row[kind]["other_songs_to_real"] > 1.0


def test_feature_gaps_name_the_feature_that_differs():
    assert len(DM.KINETIC_NAMES) == 63 and len(DM.GEOMETRIC_NAMES) == 32
    rng = np.random.default_rng(0)
    real = rng.standard_normal((40, 63))
    generated = rng.standard_normal((40, 63))
    hips_h = DM.KINETIC_NAMES.index("Hips horizontal speed²")
    generated[:, hips_h] += 5.0  # the generated set travels where the real one does not
    order = DM.feature_gaps(generated, real)
    assert order[0] == hips_h and len(order) == DM.GAPS
    term = (generated.mean(0) - real.mean(0)) ** 2
    assert term[order[1]] >= term[order[2]] and term[order[2]] >= np.delete(term, order).max()


def test_a_distance_row_reports_its_largest_gaps():
    frames = 600
    t = np.arange(frames) / FPS
    real = bent(standing(frames), "LowerArm_L", 60 + 50 * np.sin(2 * np.pi * 0.7 * t))
    # the same dance, its body gliding 1 m/s across the floor
    path = np.arange(frames)[:, None] / FPS * np.array([100.0, 0.0, 0.0])
    travelling = real.replace(lpos=real.lpos + np.pad(path[:, None], ((0, 0), (1, 20), (0, 0))))
    report = DM.feature_distances(
        [("song", "waltz", real, None, None)], [("waltz", real)], {"song": [travelling]}
    )
    gaps = report["dev"]["waltz"]["kinetic"]["largest_gaps"]
    assert all(g["feature"].endswith("horizontal speed²") for g in gaps)
    # gliding at 1 m/s adds 1 m²/s² to every joint's mean squared horizontal speed
    assert all(g["generated"] - g["real"] == pytest.approx(1.0, abs=0.05) for g in gaps)
    # the same moves shifted: the distance is where the pieces lie, not how they vary
    assert report["dev"]["waltz"]["kinetic"]["generated_spread_share"] < 0.05
    table = DM.distance_table(report)
    assert any("horizontal speed²" in line and "(spread 0%)" in line for line in table)

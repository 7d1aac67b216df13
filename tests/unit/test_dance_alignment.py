"""Beat alignment (motion.beat_warp) on synthetic data, the alignment study's measures, and the
committed per-dance table (training/dance_alignment.json)."""

from __future__ import annotations

import numpy as np
import pytest

from motion import beat_warp as BW
from motion import canonical as C
from motion.skeleton import Motion
from training import dance_alignment as DA

FPS = 30.0


def bouncing(beats: np.ndarray, seconds: float, fps: float = FPS, joints: int = 3) -> np.ndarray:
    """Positions ``(F, joints, 3)`` whose speed is zero exactly at each of ``beats`` (a joint
    moving back and forth, turning round on every beat)."""
    t = np.arange(int(seconds * fps)) / fps
    phase = np.interp(t, beats, np.arange(len(beats)))  # beat index, linear between beats
    x = np.cos(np.pi * phase)  # turns round (speed 0) at every integer phase
    pos = np.zeros((len(t), joints, 3))
    pos[..., 0] = 10.0 * x[:, None]
    return pos


def test_speed_minima_on_the_beats_score_about_one():
    beats = np.arange(0.0, 20.0, 0.5)
    kin = BW.kinematic_beats(bouncing(beats, 20.0), FPS)
    assert len(kin) >= 35
    assert np.abs(kin - np.round(kin * 2) / 2).max() < 1.0 / FPS  # found on the beats
    assert BW.beat_alignment_score(kin, beats) > 0.9
    assert BW.beat_alignment_score(kin, beats, over="music") > 0.9
    # the same motion against grids half a beat off scores about zero
    assert BW.beat_alignment_score(kin, BW.shifted_grid(beats, 0.5)) < 0.05


def test_random_kinematic_beats_score_at_chance():
    rng = np.random.default_rng(1)
    beats = np.arange(0.0, 300.0, 0.5)
    kin = np.sort(rng.uniform(1.0, 299.0, 2000))
    score = BW.beat_alignment_score(kin, beats)
    base = BW.shifted_grid_baseline(kin, beats, draws=50)
    expected = BW.SIGMA_SECONDS * np.sqrt(2 * np.pi) / 0.5  # Gaussian area over the period
    assert score == pytest.approx(expected, abs=0.03)
    assert base.mean == pytest.approx(expected, abs=0.02)
    assert abs(base.z(score)) < 3


def test_score_edge_cases():
    assert BW.beat_alignment_score([], [1.0, 2.0]) == 0.0
    assert BW.beat_alignment_score([1.0], []) == 0.0
    # kinematic beats far outside the beats' span are not scored
    assert BW.beat_alignment_score([1.0, 50.0], [0.5, 1.0, 1.5]) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        BW.beat_alignment_score([1.0], [1.0, 2.0], over="both")
    a = BW.shifted_grid_baseline([1.1, 2.2], np.arange(0, 5, 0.5), seed=3)
    b = BW.shifted_grid_baseline([1.1, 2.2], np.arange(0, 5, 0.5), seed=3)
    assert a == b and 0.0 <= a.mean <= 1.0


def test_beat_position_extrapolates():
    beats = np.array([1.0, 1.5, 2.0])
    np.testing.assert_allclose(BW.beat_position(beats, [0.5, 1.25, 2.0, 3.0]), [-1, 0.5, 2, 4])


def _canonical_bounce(beats: np.ndarray, seconds: float, shift: float) -> Motion:
    """A canonical motion whose arms turn round ``shift`` seconds after each beat."""
    frames = int(seconds * FPS)
    t = np.arange(frames) / FPS
    phase = np.interp(t - shift, beats, np.arange(len(beats)))
    angle = 0.6 * np.cos(np.pi * phase)
    lrot = np.zeros((frames, len(C.JOINTS), 4))
    lrot[..., 3] = 1.0
    for name in ("UpperArm_L", "UpperArm_R", "UpperLeg_L", "UpperLeg_R"):
        lrot[:, C.INDEX[name], 2] = np.sin(angle / 2)
        lrot[:, C.INDEX[name], 3] = np.cos(angle / 2)
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 0] = 0.0
    return Motion(C.SKELETON, FPS, lrot, lpos)


def test_warp_moves_kinematic_beats_onto_the_music():
    from motion import kinematics as K

    beats = np.arange(0.5, 12.0, 0.5)
    motion = _canonical_bounce(beats, 12.0, shift=0.12)
    before = BW.kinematic_beats(K.global_positions(motion), FPS)
    assert BW.beat_alignment_score(before, beats) < 0.2
    result = BW.warp_to_beats(motion, beats)
    after = BW.kinematic_beats(K.global_positions(result.motion), FPS)
    assert result.motion.num_frames == motion.num_frames
    assert len(result.anchors) > 15
    assert BW.beat_alignment_score(after, beats) > 0.85
    # a motion far off the beat (more than max_shift) is left alone
    far = BW.warp_to_beats(motion, beats, max_shift=0.05)
    assert len(far.anchors) == 0 and far.motion is motion


def test_a_warp_that_ends_fast_does_not_freeze_the_end():
    """The music's beats stop 6 s before the song does, after the dance has been sped up
    onto its last few: the rest of the dance still plays to the end, none of it held."""
    from motion import kinematics as K

    music = np.arange(0.5, 14.0, 0.5)
    late = np.clip(np.arange(len(music)) - (len(music) - 5), 0, None) * 0.05
    kin = np.concatenate([music + late, 14.0 + late[-1] + np.arange(0.5, 6.0, 0.5)])
    motion = _canonical_bounce(kin, 20.0, shift=0.0)
    result = BW.warp_to_beats(motion, music)
    assert len(result.anchors) > 20
    speed = BW.joint_speed(K.global_positions(result.motion), FPS)
    source = BW.joint_speed(K.global_positions(motion), FPS)
    last = int(FPS)  # the last second, a bounce and more
    assert speed[-last:].mean() > 0.5 * source[-last:].mean()


def test_match_beats_limits_the_playback_rate():
    music = np.arange(0.0, 5.0, 0.5)
    kin = music + np.array([0, 0.15, -0.15, 0.15, -0.15, 0, 0, 0, 0, 0])
    pairs = BW.match_beats(kin, music, max_stretch=1.25)
    rates = np.diff(pairs[:, 1]) / np.diff(pairs[:, 0])
    assert np.all((rates >= 0.8 - 1e-9) & (rates <= 1.25 + 1e-9))
    assert np.all(np.diff(pairs, axis=0) > 0)


def test_locking_recovers_an_injected_clock_ratio():
    """A pelvis bobbing once per 3-beat bar on a motion clock 1.2 % fast: the study finds the
    rate, the cycle and a stable phase."""
    beats = np.arange(0.0, 80.0, 60 / 87)
    frames = int(60 * DA.SOURCE_FPS)
    t = np.arange(frames) / DA.SOURCE_FPS
    bar = BW.beat_position(beats, 2.0 + 1.012 * t) / 3.0
    rng = np.random.default_rng(0)
    points = rng.normal(0, 0.3, (frames, 23, 3))
    points[:, 2, 1] += 5 * np.cos(2 * np.pi * bar)
    dance = DA.Dance("DANCE_W_0", "waltz", points, 50, 1600, beats, 87.0, np.ones(100), 80.0)
    lock = DA.tempo_lock(dance, dance.config_offset)
    assert lock.signal == "height"
    assert lock.rate == pytest.approx(1.012, abs=0.003)
    assert lock.ratio > DA.LOCK_RATIO_MIN
    assert abs(lock.half_phase_error) < DA.PHASE_TOLERANCE


def test_beat_phase_lag_wraps_within_half_a_beat():
    lag = DA.beat_phase_lag(cycle_phase=0.1, cycle=3, beat_period=0.7, psi=0.9)
    assert -0.35 <= lag <= 0.35
    assert (0.1 * 3 - lag / 0.7 - 0.9) % 1.0 == pytest.approx(0.0, abs=1e-9)


def test_the_committed_table_loads():
    table = DA.load_table()
    rows = table["dances"]
    assert len(rows) == 23
    verdicts = {r["verdict"] for r in rows.values()}
    assert verdicts <= {"verified", "rate-corrected", "unverified"}
    for row in rows.values():
        assert np.isfinite(row["use_offset_s"]) and 0.9 <= row["use_rate"] <= 1.1
        assert row["beat_phase_trusted"] == (row["verdict"] != "unverified")
    summary = table["summary"]
    assert summary["verified"] and 1.0 < summary["global_rate"] < 1.03
    alignment = DA.alignment_for(summary["verified"][0], table)
    assert alignment.trusted and alignment.rate == pytest.approx(summary["global_rate"])
    assert DA.alignment_for("DANCE_X_0", table) is None

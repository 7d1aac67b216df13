"""Training datasets as canonical motions (most tests need the shared data and skip without it)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from motion import canonical as C
from motion import kinematics as K
from tests.conftest import data_path

data = pytest.importorskip("training.data")


@pytest.fixture(scope="module")
def bandai(tmp_path_factory):
    data_path("bandai")
    return data.load_bandai()


def test_bandai_is_labelled_canonical_and_complete(bandai):
    index = data.bandai_index()
    assert len(bandai) == len(index) == 454
    frames = {r["path"].split("/")[-1][:-4]: int(r["frames"]) for r in index}
    for clip in bandai:
        assert clip.num_frames == frames[clip.name]
        assert clip.lrot.shape == (clip.num_frames, 22, 4) and np.isfinite(clip.lrot).all()
    styles = Counter(c.style for c in bandai)
    assert len(styles) == 19  # 15 + 7 minus the 3 names both datasets share
    assert styles["normal"] == 20 + 40 and styles["elderly"] == 40
    assert {c.content for c in bandai} >= {"walk", "run", "bow", "wave-left-hand"}


def test_bandai_canonical_poses_stand_on_the_floor_upright(bandai):
    for clip in bandai[::15]:
        g = K.global_positions(clip.motion)
        head_above_hips = g[:, C.INDEX["Head"], 1] - g[:, C.INDEX["Hips"], 1]
        assert np.median(head_above_hips) > 30, clip.name
        feet = g[:, [C.INDEX["Toes_L"], C.INDEX["Toes_R"]], 1].min(axis=1)
        assert abs(np.median(feet)) < 15, clip.name


def test_root_travel_kept_for_clips_that_move_joint_root(bandai):
    dash = next(c for c in bandai if c.name == "dataset-1_dash_normal_001")
    assert np.ptp(dash.root[:, 2]) > 100


def test_split_is_by_take_and_stratified(bandai):
    train, val = data.split_by_take(bandai, 0.15, seed=3)
    assert not {c.take for c in train} & {c.take for c in val}
    assert len(train) + len(val) == len(bandai)
    assert {c.style for c in val} == {c.style for c in bandai}
    again = data.split_by_take(bandai, 0.15, seed=3)[1]
    assert [c.name for c in again] == [c.name for c in val]


def test_cmu_dance_has_genres():
    data_path("cmu-dance-43")
    clips = data.load_cmu_dance()
    assert {c.genre for c in clips} == {"salsa", "indian", "modern"}
    for c in clips:
        g = K.global_positions(c.motion)
        assert np.median(g[:, C.INDEX["Head"], 1] - g[:, C.INDEX["Hips"], 1]) > 30, c.name


def test_dance_with_melody_fits_the_canonical_skeleton():
    data_path("dance-with-melody")
    clips = data.load_dance_with_melody()
    assert len(clips) == 23
    assert {c.genre for c in clips} == {"cha-cha", "rumba", "tango", "waltz"}
    for c in clips[::5]:
        # 25 fps source resampled to 30 fps over the same duration
        assert abs(c.num_frames / 30.0 - (c.extra["source_frames"] - 1) / 25.0) < 2 / 30
        g = K.global_positions(c.motion)
        assert np.median(g[:, C.INDEX["Head"], 1] - g[:, C.INDEX["Hips"], 1]) > 30, c.name
        lengths = np.linalg.norm(g[:, 8] - g[:, 7], axis=-1)  # upper arm: rigid after the fit
        assert np.ptp(lengths) < 1e-4  # rotations are stored as float32


def test_dance_with_melody_keeps_the_dancers_path():
    """The dancers cross the floor (metres); the clip's hips follow the markers' hips there.
    A root joint carrying the path (which a Clip drops) had left every dance in place."""
    data_path("dance-with-melody")
    clip = next(c for c in data.load_dance_with_melody() if c.name == "DANCE_W_14")
    points, _ = data.read_dwm_folder(data.data_dir() / "dance-with-melody" / "DANCE_W_14")
    markers = 0.5 * (points[:, 7] + points[:, 16])[:, [0, 2]]  # the hip points' middle
    hips = K.global_positions(clip.motion)[:, C.INDEX["Hips"]][:, [0, 2]]
    assert np.ptp(markers, axis=0).min() > 100.0
    np.testing.assert_allclose(np.ptp(hips, axis=0), np.ptp(markers, axis=0), atol=5.0)


def test_dance_audio_covers_the_motion():
    data_path("dance-with-melody")
    clip = next(c for c in data.load_dance_with_melody() if c.name == "DANCE_W_14")
    samples, sr = data.clip_audio(clip)
    assert abs(len(samples) / sr - clip.num_frames / 30.0) < 0.05


def test_unlabelled_motion_is_every_non_bandai_clip_without_labels():
    for folder in ("cmu-31", "xia", "cmu-dance-43", "dance-with-melody"):
        data_path(folder)
    clips = data.load_unlabelled_motion()
    assert {c.dataset for c in clips} == {"cmu-31", "xia", "cmu-dance", "dance-with-melody"}
    assert len({c.take for c in clips}) == len(clips) == 9 + 9 + 7 + 23 - 1  # 05_20 twice
    assert all(c.style is None and c.content is None and c.genre is None for c in clips)
    xia = next(c for c in clips if c.name == "angry_13_000")  # 140 frames at 120 fps
    assert abs(xia.num_frames - 140 / 4) <= 1
    for c in clips[::6]:
        g = K.global_positions(c.motion)
        assert np.median(g[:, C.INDEX["Head"], 1] - g[:, C.INDEX["Hips"], 1]) > 30, c.name


def test_a_cache_file_reads_back_without_the_data_it_was_built_from(bandai, tmp_path):
    """``read_clips`` (``fit --clips``, for a machine without the data folder) gives the
    clips a cache file holds, labels and arrays alike, whatever sources built it."""
    clips = bandai[:5]
    path = tmp_path / "some.npz"
    data.save_clips(path, clips, fingerprint="built elsewhere")
    back = data.read_clips(path)
    assert [c.name for c in back] == [c.name for c in clips]
    assert [(c.style, c.content, c.take) for c in back] == [
        (c.style, c.content, c.take) for c in clips
    ]
    for got, want in zip(back, clips, strict=True):
        np.testing.assert_array_equal(got.lrot, want.lrot)
        np.testing.assert_array_equal(got.root, want.root)
    with pytest.raises(FileNotFoundError):
        data.read_clips(tmp_path / "missing.npz")


def test_a_half_precision_copy_keeps_every_pose_within_a_tenth_of_a_degree(bandai, tmp_path):
    """``save_clips(half=True)`` (``training.carry``, for a lent machine's 64 MiB) stores
    rotations as float16: read back they are unit quaternions, each joint's rotation within
    0.1 degree of the original, and the file is at most 60% of the float32 one."""
    clips = bandai[:20]
    full, half = tmp_path / "full.npz", tmp_path / "half.npz"
    data.save_clips(full, clips, fingerprint="a")
    data.save_clips(half, clips, fingerprint="a", half=True)
    assert half.stat().st_size < 0.6 * full.stat().st_size
    back = data.read_clips(half)
    assert [c.name for c in back] == [c.name for c in clips]
    for got, want in zip(back, clips, strict=True):
        assert got.lrot.dtype == np.float32
        np.testing.assert_allclose(np.linalg.norm(got.lrot, axis=-1), 1.0, atol=1e-6)
        cos = np.abs(np.sum(got.lrot * want.lrot, axis=-1)).clip(max=1.0)
        assert np.degrees(2 * np.arccos(cos)).max() < 0.1, got.name
        np.testing.assert_array_equal(got.root, want.root)


def _save_a_cache_repeatedly(path: str) -> None:
    rng = np.random.default_rng(0)
    clips = [
        data.Clip(
            name=f"take{k}",
            dataset="made-up",
            take=f"take{k}",
            lrot=rng.normal(size=(2000, 22, 4)),
            root=rng.normal(size=(2000, 3)),
        )
        for k in range(4)
    ]
    for _ in range(6):
        data.save_clips(Path(path), clips, fingerprint="one")


def test_two_processes_building_one_cache_at_once_both_finish(tmp_path):
    """`make train-fast` trains two styles at once, each process loading the datasets: on
    a fresh clone both build the same cache file together, and neither may fail."""
    import multiprocessing

    path = tmp_path / "shared.npz"
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_save_a_cache_repeatedly, args=(str(path),)) for _ in "ab"]
    for w in workers:
        w.start()
    for w in workers:
        w.join(120)
    assert [w.exitcode for w in workers] == [0, 0]
    assert [c.name for c in data.read_clips(path)] == [f"take{k}" for k in range(4)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shared.npz"]


def test_a_missing_data_folder_is_named_not_a_numpy_error(tmp_path, monkeypatch):
    from training import data as D

    monkeypatch.setenv("MOTION_DATA_DIR", str(tmp_path / "nowhere"))
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    for load in (D.load_cmu_dance, D.load_dance_with_melody, lambda: D.load_bvh_folder("xia")):
        with pytest.raises(FileNotFoundError, match="MOTION_DATA_DIR"):
            load()

"""The shipped dance bundle: its manifest entry, its statistics, and parity of its ONNX graphs
with the checkpoint it was exported from (100 autoregressive steps)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from motion import dance_features as DF
from service.config import Settings
from service.manifest import load_manifest

torch = pytest.importorskip("torch")

MODELS = Settings().models_dir[0]


def shipped_entry():
    entry = next((m for m in load_manifest(MODELS).models if m.family == "dance"), None)
    if entry is None:
        pytest.skip(f"no dance model shipped in {MODELS}")
    return entry


def test_manifest_entry_describes_the_bundle():
    entry = shipped_entry()
    extra = entry.extra
    assert set(extra["genres"]) == set(DF.GENRES)
    assert extra["fps"] == DF.FPS
    assert {"audio", "step"} <= set(entry.graphs)
    checks = entry.metrics["parity_max_abs"]
    assert checks["steps"] >= 100 and checks["step"] < 1e-3 and checks["audio"] < 1e-3
    assert checks["step_int8"] < entry.metrics["parity_int8_atol"]
    stats = DF.DanceStats.load(MODELS / extra["stats"])
    assert stats.audio_mean.shape == (DF.AUDIO_CHANNELS,)
    assert stats.motion_mean.shape == (DF.MOTION_CHANNELS,)
    assert np.all(stats.motion_std > 0) and np.all(stats.audio_std > 0)


def test_shipped_graphs_match_the_checkpoint(tmp_path):
    from model_export import dance as ED
    from training import dance as TD

    entry = shipped_entry()
    if not TD.CHECKPOINT.exists():
        pytest.skip(f"no checkpoint at {TD.CHECKPOINT}")
    copy = tmp_path / "dance.pt"
    shutil.copy2(TD.CHECKPOINT, copy)  # a running training overwrites the original
    model, stats, ckpt = TD.load_checkpoint(copy)
    if int(ckpt["step"]) != int(entry.metrics["steps"]):
        pytest.skip(f"checkpoint is at step {ckpt['step']}, the shipped model at "
                    f"{entry.metrics['steps']}")  # fmt: skip
    figures = ED.parity(model, MODELS / ED.FOLDER, seed=1, int8=True)  # raises outside tolerance
    assert figures["steps"] == ED.PARITY_STEPS >= 100
    shipped = DF.DanceStats.load(MODELS / entry.extra["stats"])
    np.testing.assert_array_equal(shipped.motion_mean, stats.motion_mean)
    np.testing.assert_array_equal(shipped.audio_std, stats.audio_std)
    assert entry.extra["validation_takes"] == list(TD.held_out_takes(ckpt))  # eval's songs

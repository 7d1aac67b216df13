"""Fast style networks (holden2017): shapes, losses, smoke training of both scripts, and
ONNX parity of exported graphs with torch."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from motion import bvh, retarget  # noqa: E402
from motion import fast_features as FF  # noqa: E402
from tests.rigs import FIXTURE  # noqa: E402
from training import fast_common as FC  # noqa: E402


@pytest.fixture(scope="module")
def walk_features():
    motion = bvh.load(FIXTURE)
    canon = retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion))
    return FF.encode(canon).features


@pytest.mark.parametrize("frames", [1, 31, 32, 100, 241])
def test_networks_keep_length(frames):
    x = torch.randn(2, frames, FF.CHANNELS)
    ae = FC.Autoencoder(hidden=32).eval()
    assert ae.encode(x).shape == (2, 32, (frames + 1) // 2)
    assert ae(x).shape == x.shape
    assert FC.StyleNet(hidden=16)(x).shape == x.shape


def test_style_net_starts_as_identity():
    x = torch.randn(1, 50, FF.CHANNELS)
    torch.testing.assert_close(FC.StyleNet()(x), x)


def test_pooling_is_ceil_mode():
    h = torch.randn(2, 5, 7)
    padded = torch.nn.functional.pad(h, (0, 1), value=-1e9)
    want = torch.nn.functional.max_pool1d(h, 2, ceil_mode=True)
    torch.testing.assert_close(torch.nn.functional.max_pool1d(padded, 2), want)


def test_bone_loss_on_real_motion(walk_features):
    stats = FF.FastStats.fit([walk_features])
    physics = FC.Physics(stats.mean, stats.std)
    raw = physics.raw(torch.tensor(stats.normalize(walk_features))[None])
    assert physics.bone_loss(raw).item() < 1e-6  # real positions keep their bones
    stretched = raw.clone()
    stretched[..., : FF.POSITION_CHANNELS] *= 1.1
    assert physics.bone_loss(stretched).item() > 1e-4


def test_export_parity(tmp_path):
    """Exported graphs: symbolic batch/time, and onnxruntime equals torch (rtol 1e-4) at
    T = 32, 100, 241 and batch 1 and 3."""
    from model_export import fast as X

    assert {(b, t) for b, t in X.PARITY_SHAPES} == {(b, t) for b in (1, 3) for t in (32, 100, 241)}
    torch.manual_seed(0)
    ae = FC.Autoencoder().eval()
    style = FC.StyleNet().eval()
    torch.nn.init.normal_(style.layers[-1].weight, std=0.02)  # not the identity
    for name, module, output in (
        ("projection", FC.Projection(ae), "projected"),
        ("style", style, "styled"),
    ):
        path = tmp_path / f"{name}.onnx"
        X.export_graph(module, path, output)
        assert X.parity(module, path) < 1e-3
        assert not list(tmp_path.glob("*.data"))  # single file


def test_smoke_training_and_export(tmp_path, monkeypatch, data_dir):
    """Both training scripts for a few steps (the style networks distilled from the shipped
    translator's outputs for four Bandai takes), then the export into a copy of the shipped
    models folder; the manifest entry validates, lists every graph with its sha256 and
    takes its style's speed from the translator."""
    import shutil

    from model_export import fast as X
    from service.config import Settings
    from service.manifest import load_manifest, verify_files
    from training import fast_autoencoder, fast_style

    monkeypatch.setenv("MOTION_SMOKE", "1")
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    ckpt, logs, models = tmp_path / "ckpt", tmp_path / "runs", tmp_path / "models"
    common = ["--checkpoint-dir", str(ckpt), "--log-dir", str(logs)]
    result = fast_autoencoder.main([*common, "--hidden", "32", "--batch", "4"])
    assert result["step"] == 3 and np.isfinite(result["val_mse"])
    split = json.loads((ckpt / "split.json").read_text())
    assert split["seed"] == FC.SPLIT_SEED and split["validation_takes"]
    summary = fast_style.main([*common, "--style", "angry", "--batch", "4", "--hidden", "8"])
    assert summary["angry"]["steps"] == 3
    assert all(np.isfinite(v) for v in summary["angry"]["train"].values())
    assert (logs / "style_angry" / "log.txt").exists()

    shutil.copytree(Settings().models_dir, models)
    X.main(["--checkpoint-dir", str(ckpt), "--models-dir", str(models)])
    manifest = load_manifest(models)
    entry = next(m for m in manifest.models if m.family == "fast")
    teacher = next(m for m in manifest.models if m.family == "translator")
    assert set(entry.graphs) == {"projection", "style_angry"}
    assert verify_files(entry, models) == []
    assert entry.extra["styles"]["angry"]["speed"] == teacher.extra["styles"]["angry"]["speed"]
    assert entry.extra["teacher"] == f"{teacher.name} {teacher.version}"
    assert "research and evaluation only" in entry.licence

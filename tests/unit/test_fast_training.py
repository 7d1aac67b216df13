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


def test_physics_losses_on_real_motion(walk_features):
    stats = FF.FastStats.fit([walk_features])
    physics = FC.Physics(stats.mean, stats.std)
    z = torch.tensor(stats.normalize(walk_features))[None]
    raw = physics.raw(z)
    planted = raw[..., FF.CONTACTS] > 0.5
    assert physics.bone_loss(raw).item() < 1e-6  # real positions keep their bones
    still = physics.foot_loss(raw, planted).item()
    assert still < 0.05  # planted feet barely move (leg lengths / s, squared)
    slid = raw.clone()
    slid[..., FF.VELOCITY] += 0.5  # the root moves but the feet stay put in its frame
    assert physics.foot_loss(slid, planted).item() > still + 0.2
    stretched = raw.clone()
    stretched[..., : FF.POSITION_CHANNELS] *= 1.1
    assert physics.bone_loss(stretched).item() > 1e-4


def test_gram_is_time_averaged():
    h = torch.randn(3, 8, 40)
    g = FC.gram(h)
    assert g.shape == (3, 8, 8)
    torch.testing.assert_close(FC.gram(torch.cat([h, h], dim=-1)), g)


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
    """Both training scripts for a few steps, then the export into a temporary models
    folder; the manifest entry validates and lists every graph with its sha256."""
    from model_export import fast as X
    from service.manifest import load_manifest, verify_files
    from training import fast_autoencoder, fast_style

    monkeypatch.setenv("MOTION_SMOKE", "1")
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

    models.mkdir()
    X.main(["--checkpoint-dir", str(ckpt), "--models-dir", str(models)])
    manifest = load_manifest(models)
    (entry,) = manifest.models
    assert entry.family == "fast"
    assert set(entry.graphs) == {"projection", "style_angry"}
    assert verify_files(entry, models) == []
    assert entry.extra["styles"]["angry"]["clips"] > 0
    assert "research and evaluation only" in entry.licence

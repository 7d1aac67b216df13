"""Fast style networks: shapes, receptive field, smoke training, and ONNX parity of
exported graphs with torch."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from motion import features as Fe  # noqa: E402
from training import fast_common as FC  # noqa: E402


@pytest.mark.parametrize("frames", [1, 31, 100, 241])
def test_network_keeps_length(frames):
    x = torch.randn(2, Fe.CONTROL_CHANNELS, frames)
    assert FC.StyleNet(hidden=16)(x).shape == (2, Fe.OUTPUT_CHANNELS, frames)


def test_receptive_field_is_what_the_network_sees():
    """A change at one frame moves outputs exactly ``receptive_field()`` frames either side."""
    torch.manual_seed(0)
    net = FC.StyleNet(hidden=8).eval()
    x = torch.randn(1, Fe.CONTROL_CHANNELS, 201)
    bumped = x.clone()
    bumped[..., 100] += 1.0
    with torch.no_grad():
        moved = (net(bumped) - net(x)).abs().amax(dim=1)[0] > 0
    reach = FC.receptive_field()
    assert torch.nonzero(moved).flatten().tolist() == list(range(100 - reach, 100 + reach + 1))


def test_export_parity(tmp_path):
    """Exported graphs: symbolic batch/time, weights stored as float16, and onnxruntime
    equals torch with its weights rounded as stored (rtol 1e-4) at T = 32, 100, 241 and
    batch 1 and 3, in a single file."""
    import onnx
    from onnx import numpy_helper

    from model_export import fast as X

    assert {(b, t) for b, t in X.PARITY_SHAPES} == {(b, t) for b in (1, 3) for t in (32, 100, 241)}
    torch.manual_seed(0)
    net = FC.StyleNet().eval()
    path = tmp_path / "style.onnx"
    X.export_graph(net, path)
    assert X.parity(X.halved(net), path) < 1e-3
    assert not list(tmp_path.glob("*.data"))
    weights = [numpy_helper.to_array(w) for w in onnx.load(str(path)).graph.initializer]
    stored = sum(w.size for w in weights if w.dtype == np.float16)
    assert stored == sum(p.numel() for p in net.parameters())
    assert path.stat().st_size < 2.2 * stored


def test_parity_tells_rounded_weights_from_the_originals(tmp_path):
    """The float16 graph differs from the unrounded network by more than the parity check
    allows, so the check compares like with like."""
    from model_export import fast as X

    torch.manual_seed(0)
    net = FC.StyleNet().eval()
    path = tmp_path / "style.onnx"
    X.export_graph(net, path)
    with pytest.raises(RuntimeError, match="parity fails"):
        X.parity(net, path)


def test_smoke_training_and_export(tmp_path, monkeypatch, data_dir):
    """The style network distilled for a few steps from the shipped translator's outputs
    for four Bandai takes, then exported into a copy of the shipped models folder; the
    manifest entry validates, lists every graph with its sha256, carries the translator's
    statistics and takes its style's speed from it. Angry has no held-out takes to measure
    the output smoothing on: the export says so, and takes it set by hand."""
    import shutil

    from model_export import fast as X
    from service.config import Settings
    from service.manifest import load_manifest, verify_files
    from training import fast_style

    monkeypatch.setenv("MOTION_SMOKE", "1")
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))
    ckpt, logs, models = tmp_path / "ckpt", tmp_path / "runs", tmp_path / "models"
    common = ["--checkpoint-dir", str(ckpt), "--log-dir", str(logs)]
    summary = fast_style.main([*common, "--style", "angry", "--batch", "4", "--hidden", "8"])
    assert summary["angry"]["steps"] == 3 and np.isfinite(summary["angry"]["train_l1"])
    assert (logs / "style_angry" / "log.txt").exists()

    shutil.copytree(Settings().models_dir[0], models)
    with pytest.raises(ValueError, match="no held-out take is in one of its styles"):
        X.main(["--checkpoint-dir", str(ckpt), "--models-dir", str(models)])  # angry alone
    X.main(["--checkpoint-dir", str(ckpt), "--models-dir", str(models), "--output-smoothing", "0"])
    manifest = load_manifest(models)
    entry = next(m for m in manifest.models if m.family == "fast")
    teacher = next(m for m in manifest.models if m.family == "translator")
    assert set(entry.graphs) == {"style_angry"} and entry.extra["output_smoothing"] == 0.0
    assert verify_files(entry, models) == []
    assert entry.extra["styles"]["angry"]["speed"] == teacher.extra["styles"]["angry"]["speed"]
    assert entry.extra["teacher"] == f"{teacher.name} {teacher.version}"
    assert (models / entry.extra["stats"]).read_bytes() == (
        models / teacher.extra["stats"]
    ).read_bytes()
    assert "research and evaluation only" in entry.licence


def test_the_targets_are_what_a_transfer_decodes():
    """The fast networks learn ``restyled(restyler_input(clip))``: exactly the restyler's
    blended output that the translator's core finishes (and hinges) into its transfer of
    the clip."""
    from motion import bvh, retarget
    from motion import features as Fe
    from service.engines.restyling import anatomical, restyled_motion
    from service.engines.translator import TransferJob
    from service.metrics import StageTimer
    from tests.rigs import FIXTURE
    from training.judges import load_engine

    engine = load_engine("translator")[0]
    clip = retarget.to_canonical(bvh.load(FIXTURE))
    style = engine.code_of_name("angry")
    timer = StageTimer(engine.name)
    job = TransferJob(clip, style, time_warp=False)
    transferred = engine.predict(job, timer).motion
    target = engine.restyled(engine.restyler_input(clip), style.code)
    finished = restyled_motion(
        target, clip, Fe.encode(clip), engine.stats, timer, engine.output_smoothing
    )
    np.testing.assert_array_equal(anatomical(finished, None, clip).lrot, transferred.lrot)

"""ONNX export of the translator (``model_export.translator``): symbolic axes, parity with
torch, the receptive field, the style table, and the shipped bundle in ``models/translator``."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from model_export import translator as X  # noqa: E402
from motion import bvh, retarget  # noqa: E402
from motion import features as Fe  # noqa: E402
from service.manifest import load_manifest, verify_files  # noqa: E402
from tests.rigs import FIXTURE  # noqa: E402
from training.translator.model import (  # noqa: E402
    AMPLITUDE_PARAMETERS,
    MIX_GAIN,
    ModelConfig,
    Translator,
)

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
CHECKPOINT = REPO / "checkpoints" / "translator.pt"


def tiny_config() -> ModelConfig:
    return ModelConfig(
        content_channels=[16, 24],
        style_channels=[16, 16, 24],
        style_dim=16,
        mlp_hidden=24,
        disc_channels=[8, 8, 8],
    )


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> tuple[Translator, dict[str, Path]]:
    torch.manual_seed(0)
    g = Translator(tiny_config()).eval()
    paths = X.export_graphs(g, tmp_path_factory.mktemp("translator"))
    return g, paths


def test_every_graph_is_one_file_with_symbolic_batch_and_time(tiny):
    g, paths = tiny
    assert sorted(paths) == sorted(X.GRAPH_NAMES)
    io = X.graph_io(g)
    for graph, path in paths.items():
        assert list(path.parent.iterdir()) and not list(path.parent.glob("*.data"))
        shapes = X.onnx_shapes(path)
        inputs, outputs = io[graph]
        for name, _ in inputs + outputs:
            dims = shapes[name]
            assert isinstance(dims[0], str) and dims[0] == "batch", (graph, name, dims)
            if len(dims) == 3:  # (batch, channels, time)
                assert isinstance(dims[1], int) and isinstance(dims[2], str) and dims[2], dims
        for name, _ in inputs:  # every input: all non-channel dims symbolic
            dims = shapes[name]
            assert all(isinstance(d, str) and d for i, d in enumerate(dims) if i != 1), dims


def test_parity_with_torch_at_several_lengths_and_batches(tiny):
    g, paths = tiny
    figures = X.parity(g, paths)  # raises outside rtol 1e-4 / atol 5e-5
    assert set(figures) == set(X.GRAPH_NAMES)
    for graph, fig in figures.items():
        assert fig["max_abs"] < X.ATOL, (graph, fig)
    assert {32, 64, 256} <= set(X.PARITY_LENGTHS) and any(t % 4 for t in X.PARITY_LENGTHS)
    assert set(X.PARITY_BATCHES) == {1, 3}


def test_parity_with_kept_amplitudes(tmp_path):
    torch.manual_seed(1)
    g = Translator(dataclasses.replace(tiny_config(), keep_amplitude=True)).eval()
    with torch.no_grad():  # trained-looking: some amplitude kept, references off zero
        for name, p in g.named_parameters():
            if name.endswith(AMPLITUDE_PARAMETERS):
                p.normal_(0.0, 0.5)
    paths = X.export_graphs(g, tmp_path)
    figures = X.parity(g, paths)  # raises outside rtol 1e-4 / atol 5e-5
    assert all(fig["max_abs"] < X.ATOL for fig in figures.values()), figures


def test_parity_with_style_mixed_kernels(tmp_path):
    torch.manual_seed(2)
    g = Translator(dataclasses.replace(tiny_config(), style_kernels=3)).eval()
    with torch.no_grad():  # trained-looking: clips mix their kernels unevenly
        g.decoder.mix.weight.normal_(0.0, 0.1)
        style = torch.randn(2, g.decoder.mix.in_features)
        mix = torch.softmax(MIX_GAIN * g.decoder.mix(style), dim=-1)
    assert float((mix - 1 / 3).abs().max()) > 0.1  # the mix matters to what is compared
    paths = X.export_graphs(g, tmp_path)
    figures = X.parity(g, paths)  # raises outside rtol 1e-4 / atol 5e-5
    assert all(fig["max_abs"] < X.ATOL for fig in figures.values()), figures


def test_parity_check_catches_a_wrong_graph(tiny, tmp_path):
    g, paths = tiny
    other = Translator(tiny_config()).eval()  # other random weights
    with pytest.raises(RuntimeError, match="parity fails"):
        X.parity(other, {"style3d": paths["style3d"]}, lengths=(32,), batches=(1,))


def test_receptive_field_matches_the_convolutions(monkeypatch):
    cfg = tiny_config()
    g = Translator(cfg).eval()
    # instance norm sees the whole clip; without it the convolutions alone set the field
    monkeypatch.setattr(torch.nn.functional, "instance_norm", lambda x, *a, **k: x)
    x = torch.randn(1, cfg.content_in, 256, requires_grad=True)
    y = g.decoder(g.content_encoder(x), torch.randn(1, cfg.style_dim))
    y[0, :, 128].sum().backward()
    seen = (x.grad[0].abs().sum(0) > 0).nonzero().flatten()
    width = int(seen.max() - seen.min() + 1)
    assert width <= X.receptive_field(cfg) <= width + 1


def test_style_table_means_training_clips_and_leaves_validation_out(tiny):
    g, _ = tiny
    source = bvh.load(FIXTURE)
    canon = retarget.to_canonical(source)
    stats = Fe.compute_stats(
        {
            "content": [Fe.encode(canon).content],
            "style3d": [Fe.encode(canon).style3d],
            "style2d": [np.zeros((4, Fe.STYLE2D_CHANNELS), np.float32)],
        }
    )
    clips = [
        SimpleNamespace(style="a", content="walk", take="a1", motion=canon.slice(0, 30)),
        SimpleNamespace(style="a", content="walk", take="a2", motion=canon.slice(10, 50)),
        SimpleNamespace(style="b", content="walk", take="b1", motion=canon.slice(5, 47)),
        SimpleNamespace(
            style="b", content="walk", take="b2", motion=canon.slice(20, 60)
        ),  # held out
        SimpleNamespace(style="c", content="walk", take="c1", motion=canon.slice(0, 20)),  # unknown
    ]
    table = X.style_table(g.style3d, stats, clips, ["a", "b"], ["b2"])
    assert table["names"] == ["a", "b"]
    assert table["clips"].tolist() == [2, 1]
    codes = [X.clip_code(g.style3d, Fe.encode(c.motion).style3d, stats) for c in clips[:3]]
    np.testing.assert_allclose(table["codes"][0], (codes[0] + codes[1]) / 2, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(table["codes"][1], codes[2], rtol=1e-5, atol=1e-6)
    want = (Fe.velocity_factor(clips[0].motion) + Fe.velocity_factor(clips[1].motion)) / 2
    assert table["velocity"][0] == pytest.approx(want)
    # two styles on one content: speeds are their velocity ratio, split evenly in log
    ratio = want / Fe.velocity_factor(clips[2].motion)
    assert table["speed"][0] == pytest.approx(ratio**0.5) and table["speed"][1] == pytest.approx(
        ratio**-0.5
    )
    assert table["val_clips"] == 1 and table["val_top1"] in (0.0, 1.0)


def test_style_speeds_compare_styles_on_the_same_content():
    # "fast" is 2x "slow" on walks and on bows; bows are 10x slower than walks; "solo"
    # alone on its content says nothing
    velocity = {
        ("walk", "fast"): [200.0], ("walk", "slow"): [90.0, 110.0],
        ("bow", "fast"): [20.0], ("bow", "slow"): [10.0],
        ("run", "solo"): [300.0],
    }  # fmt: skip
    speeds = X.style_speeds(velocity)
    assert speeds["fast"] == pytest.approx(2**0.5) and speeds["slow"] == pytest.approx(2**-0.5)
    assert speeds["solo"] == 1.0


# --------------------------------------------------------------------------- shipped bundle


def shipped_entry():
    if not (MODELS / "translator").exists():
        pytest.skip("no translator model shipped in models/translator")
    manifest = load_manifest(MODELS)
    entries = [m for m in manifest.models if m.name == X.MODEL_NAME]
    assert entries, "models/translator exists but the manifest has no translator-bandai entry"
    return entries[0]


def test_shipped_bundle_is_listed_hashed_and_small():
    entry = shipped_entry()
    assert entry.family == "translator"
    assert "CC BY-NC 4.0" in entry.licence and "research and evaluation only" in entry.licence
    assert verify_files(entry, MODELS) == []
    assert sorted(entry.graphs) == sorted(X.GRAPH_NAMES)
    for graph, spec in entry.graphs.items():
        path = MODELS / spec.file
        assert path.stat().st_size < 30 * 1024 * 1024, graph
        shapes = X.onnx_shapes(path)
        assert spec.opset >= 17
        for tensor in spec.inputs + spec.outputs:
            assert shapes[tensor.name] == tensor.shape, (graph, tensor.name)
            assert tensor.shape[0] == "batch"
    extra = entry.extra
    assert entry.version == f"0.1.{extra['step']}"
    with np.load(MODELS / extra["styles_file"]) as table:
        names = [str(n) for n in table["names"]]
        assert names == list(extra["styles"])
        for i, name in enumerate(names):
            info = extra["styles"][name]
            np.testing.assert_allclose(info["code"], table["codes"][i], atol=1e-5)
            assert info["clips"] == int(table["clips"][i]) > 0
            assert info["velocity_factor"] == pytest.approx(float(table["velocity"][i]), abs=1e-3)
            assert info["speed"] == pytest.approx(float(table["speed"][i]), abs=1e-3)
            assert len(info["code"]) == extra["style_dim"]
    split = json.loads((MODELS / extra["split"]).read_text())
    assert len(split["val_takes"]) == extra["validation_takes"] > 0
    Fe.load_stats(MODELS / extra["stats"])  # readable, every kind present
    for metric in ("rec_pos_cm", "style_acc_3d", "parity"):
        assert metric in entry.metrics


def test_shipped_graphs_match_the_checkpoint(tmp_path):
    entry = shipped_entry()
    if not CHECKPOINT.exists():
        pytest.skip(f"no checkpoint at {CHECKPOINT}")
    copy = tmp_path / "translator.pt"
    shutil.copy2(CHECKPOINT, copy)  # a running training overwrites the original
    g, stats, meta = X.load_checkpoint_copy(copy)
    if int(meta["step"]) != int(entry.extra["step"]):
        pytest.skip(
            f"checkpoint is at step {meta['step']}, the shipped model at {entry.extra['step']}"
        )
    paths = {graph: MODELS / spec.file for graph, spec in entry.graphs.items()}
    figures = X.parity(g, paths, lengths=(32, 100), batches=(1, 3))
    assert all(f["max_abs"] < X.ATOL for f in figures.values()), figures
    # the service decodes in windows of the length the model trained on (32 before bundles said)
    assert int(entry.extra.get("window", 32)) == int(meta["train_config"]["window"])
    shipped = Fe.load_stats(MODELS / entry.extra["stats"])
    for kind in Fe.KINDS:
        np.testing.assert_array_equal(shipped.mean[kind], stats.mean[kind])

"""Export the aberman2020 translator to ONNX, with its statistics and style table.

    python -m model_export.translator [--checkpoint checkpoints/translator.pt] [--models-dir models]

The checkpoint is copied to a temporary file first (a running training overwrites it every
few minutes). Writes ``models/translator/``:

- four single-file graphs with symbolic ``batch`` and time axes (``(B, C, T)``, ``T`` a
  multiple of ``STRIDE``): ``content_encoder.onnx`` (``content (B, 130, time) -> code
  (B, C_z, code_time)``), ``style3d.onnx`` (``motion3d (B, 63, time) -> style_code
  (B, S)``), ``style2d.onnx`` (``motion2d (B, 32, time) -> style_code``), ``decoder.onnx``
  (``code``, ``style_code`` -> ``output (B, 126, time)``), each checked against torch at
  :data:`PARITY_LENGTHS` x :data:`PARITY_BATCHES` (rtol :data:`RTOL`, atol :data:`ATOL`);
- ``stats.npz``: the checkpoint's feature statistics (``motion.features.save_stats``);
- ``styles.npz``: per style name (``names``) the mean 3D style code of its training clips
  (``codes (N, S)``; whole clips padded to the stride, the checkpoint's validation takes left
  out), the clip count (``clips``), the mean velocity factor of those clips (``velocity``,
  ``motion.features.velocity_factor``) and the style's ``speed`` (:func:`style_speeds`),
  the time warp of a named style;
- ``split.json``: the validation takes, for the evaluation.

and one manifest entry ``translator-bandai`` (``model_export.manifest.put_entry``) whose
``extra`` repeats the style table (codes, clip counts, velocity factors, speeds) and the
step.

The TorchScript exporter (``dynamo=False``) is used: it keeps the named time axes symbolic
and the graphs need nothing it lacks (convolutions, instance norm, nearest resize, amax).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import tempfile
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from model_export import manifest as MF
from motion import features as Fe
from training.translator.model import STRIDE, Translator, pad_time

OPSET = 17
MODEL_NAME = "translator-bandai"
FOLDER = "translator"
PARITY_LENGTHS = (32, 64, 99, 256)  # 99 is padded to the stride (100)
PARITY_BATCHES = (1, 3)
RTOL, ATOL = 1e-4, 5e-5
TRAINING_DATA = ["Bandai-Namco-Research-Motiondataset 1 and 2 (CC BY-NC 4.0)"]
LICENCE = (
    "research and evaluation only: trained on Bandai Namco Research Motion dataset, CC BY-NC 4.0"
)
GRAPH_NAMES = ("content_encoder", "style3d", "style2d", "decoder")


def graph_io(g: Translator) -> dict[str, tuple[list, list]]:
    """Per graph ``(inputs, outputs)`` as ``(name, shape)`` pairs (symbolic dims as names)."""
    cfg = g.cfg
    code = cfg.content_channels[-1]
    code_shape = ["batch", code, "code_time"]
    style = [("style_code", ["batch", cfg.style_dim])]
    return {
        "content_encoder": ([("content", ["batch", cfg.content_in, "time"])], [("code", code_shape)]),
        "style3d": ([("motion3d", ["batch", cfg.style3d_in, "time"])], style),
        "style2d": ([("motion2d", ["batch", cfg.style2d_in, "time"])], style),
        "decoder": ([("code", code_shape), *style], [("output", ["batch", cfg.output, "time"])]),
    }  # fmt: skip


def receptive_field(cfg) -> int:
    """Frames of content input that one output frame of ``decoder(content_encoder(x))`` sees
    through its convolutions (instance norm aside, which sees the whole clip)."""
    k, rf, jump = cfg.kernel, 1, 1
    rf += (k - 1) * jump  # first
    for _ in range(cfg.content_down):  # kernel 4, stride 2
        rf += 3 * jump
        jump *= 2
    rf += 2 * cfg.content_resblocks * (k - 1) * jump
    rf += 2 * cfg.decoder_resblocks * (k - 1) * jump
    for _ in range(cfg.content_down):  # nearest x2, then a convolution
        jump //= 2
        rf += 1 + (k - 1) * jump
    return rf + (k - 1) * jump  # last


def _example_inputs(g: Translator, graph: str, batch: int, frames: int, gen=None) -> tuple:
    """Standard-normal inputs of ``graph`` for ``frames`` frames (a multiple of STRIDE)."""
    cfg = g.cfg

    def randn(*shape):
        return torch.randn(*shape, generator=gen)

    if graph == "content_encoder":
        return (randn(batch, cfg.content_in, frames),)
    if graph == "style3d":
        return (randn(batch, cfg.style3d_in, frames),)
    if graph == "style2d":
        return (randn(batch, cfg.style2d_in, frames),)
    with torch.no_grad():
        code = g.content_encoder(randn(batch, cfg.content_in, frames))
        style = g.style3d(randn(batch, cfg.style3d_in, frames))
    return code, style


def export_graphs(g: Translator, out_dir: Path) -> dict[str, Path]:
    """The four graphs of ``g`` as ``out_dir/<graph>.onnx`` (single files, symbolic axes)."""
    g.eval()
    out_dir.mkdir(parents=True, exist_ok=True)
    io = graph_io(g)
    paths = {}
    for graph in GRAPH_NAMES:
        inputs, outputs = io[graph]
        axes = {
            name: {i: d for i, d in enumerate(shape) if isinstance(d, str)}
            for name, shape in inputs + outputs
        }
        path = out_dir / f"{graph}.onnx"
        with warnings.catch_warnings(), torch.no_grad():
            warnings.simplefilter("ignore")
            torch.onnx.export(
                getattr(g, graph),
                _example_inputs(g, graph, 1, 64),
                str(path),
                dynamo=False,
                opset_version=OPSET,
                input_names=[n for n, _ in inputs],
                output_names=[n for n, _ in outputs],
                dynamic_axes=axes,
            )
        check_symbolic(path, inputs, outputs)
        paths[graph] = path
    return paths


def onnx_shapes(path: Path) -> dict[str, list]:
    """``{tensor: dims}`` of a graph's inputs and outputs (symbolic dims as names)."""
    import onnx

    model = onnx.load(str(path))
    onnx.checker.check_model(model)
    return {
        v.name: [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]
        for v in list(model.graph.input) + list(model.graph.output)
    }


def check_symbolic(path: Path, inputs: list, outputs: list) -> None:
    """Every input and output has exactly the declared dims: the named ones symbolic."""
    shapes = onnx_shapes(path)
    for name, shape in inputs + outputs:
        if shapes.get(name) != shape:
            raise RuntimeError(f"{path.name}: {name} has dims {shapes.get(name)}, want {shape}")


def parity(
    g: Translator,
    paths: dict[str, Path],
    lengths: Iterable[int] = PARITY_LENGTHS,
    batches: Iterable[int] = PARITY_BATCHES,
    rtol: float = RTOL,
    atol: float = ATOL,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Torch vs onnxruntime for every graph at every length (padded to STRIDE) and batch:
    ``{graph: {"max_abs", "max_rel"}}``; raises ``RuntimeError`` when an element is
    outside ``rtol``/``atol``."""
    import onnxruntime as ort

    gen = torch.Generator().manual_seed(seed)
    g.eval()
    out: dict[str, dict[str, float]] = {}
    for graph, path in paths.items():
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        names = [i.name for i in session.get_inputs()]
        worst_abs = worst_rel = 0.0
        for frames in lengths:
            padded = frames + (-frames) % STRIDE
            for batch in batches:
                if graph == "decoder":  # the code of a padded clip: T / 2 steps
                    x = _example_inputs(g, graph, batch, padded, gen)
                else:
                    x = (pad_time(_example_inputs(g, graph, batch, frames, gen)[0]),)
                with torch.no_grad():
                    want = getattr(g, graph)(*x).numpy()
                got = session.run(None, dict(zip(names, (t.numpy() for t in x), strict=True)))[0]
                if got.shape != want.shape or not np.allclose(got, want, rtol=rtol, atol=atol):
                    diff = np.abs(got - want).max() if got.shape == want.shape else float("nan")
                    raise RuntimeError(
                        f"{path.name}: parity fails at batch {batch}, time {frames} "
                        f"(max abs {diff:.2e}, shapes {got.shape} vs {want.shape})"
                    )
                diff = np.abs(got - want)
                worst_abs = max(worst_abs, float(diff.max()))
                worst_rel = max(worst_rel, float((diff / (np.abs(want) + 1e-3)).max()))
        out[graph] = {"max_abs": worst_abs, "max_rel": worst_rel}
    return out


# --------------------------------------------------------------------------- style table


def clip_code(style3d_net, style3d: np.ndarray, stats: Fe.FeatureStats) -> np.ndarray:
    """3D style code ``(S,)`` of a whole clip's raw style3d features ``(F, 63)`` (padded to
    the stride by repeating the last frame), ``style3d_net`` a torch module or a callable
    on a ``(1, 63, T)`` float32 array."""
    x = Fe.pad_frames(Fe.standardize(style3d, stats, "style3d"), STRIDE).T[None]
    if isinstance(style3d_net, torch.nn.Module):
        with torch.no_grad():
            return style3d_net(torch.from_numpy(np.ascontiguousarray(x))).numpy()[0]
    return np.asarray(style3d_net(np.ascontiguousarray(x)))[0]


def style_speeds(velocity: dict[tuple[str, str], list[float]]) -> dict[str, float]:
    """How fast each style moves against the others *on the same content*: per content,
    the log of a style's mean velocity factor minus the mean of that over the content's
    styles; a style's speed is the exp of its mean over its contents (contents with one
    style say nothing and are skipped; a style with none gets 1).

    A style's plain mean velocity factor mixes its contents: runs are fast and bows slow,
    so warping by it slowed every run and sped up every bow, whatever the style.
    ``velocity``: ``(content, style) -> velocity factors``.
    """
    logs = {k: float(np.log(np.mean(v))) for k, v in velocity.items() if np.mean(v) > 1e-6}
    by_content: dict[str, dict[str, float]] = {}
    for (content, style), value in logs.items():
        by_content.setdefault(content, {})[style] = value
    offsets: dict[str, list[float]] = {}
    for per_style in by_content.values():
        if len(per_style) < 2:
            continue
        mean = float(np.mean(list(per_style.values())))
        for style, value in per_style.items():
            offsets.setdefault(style, []).append(value - mean)
    styles = {style for _, style in velocity}
    return {s: float(np.exp(np.mean(offsets[s]))) if s in offsets else 1.0 for s in styles}


def style_table(
    style3d_net, stats: Fe.FeatureStats, clips: list, styles: list[str], val_takes: Iterable[str]
) -> dict:
    """Mean code, clip count, mean velocity factor and speed (:func:`style_speeds`) per
    style over the training clips (those whose take is not in ``val_takes``), and the
    validation clips' nearest-style accuracy (top 1 and top 3, by Euclidean distance to
    the means).

    ``clips``: ``training.data.Clip`` objects with ``style``, ``content``, ``take`` and
    ``motion``.
    """
    held_out = set(val_takes)
    codes: dict[str, list[np.ndarray]] = {s: [] for s in styles}
    velocity: dict[str, list[float]] = {s: [] for s in styles}
    by_content: dict[tuple[str, str], list[float]] = {}
    val: list[tuple[str, np.ndarray]] = []
    for clip in clips:
        if clip.style not in codes:
            continue
        motion = clip.motion
        enc = Fe.encode(motion)
        code = clip_code(style3d_net, enc.style3d, stats)
        if clip.take in held_out:
            val.append((clip.style, code))
            continue
        codes[clip.style].append(code)
        velocity[clip.style].append(Fe.velocity_factor(motion))
        by_content.setdefault((clip.content, clip.style), []).append(velocity[clip.style][-1])
    names = [s for s in styles if codes[s]]
    speeds = style_speeds(by_content)
    table = {
        "names": names,
        "codes": np.stack([np.mean(codes[s], axis=0) for s in names]).astype(np.float32),
        "clips": np.array([len(codes[s]) for s in names], dtype=np.int64),
        "velocity": np.array([np.mean(velocity[s]) for s in names], dtype=np.float64),
        "speed": np.array([speeds[s] for s in names], dtype=np.float64),
    }
    hits1 = hits3 = 0
    for style, code in val:
        order = np.argsort(np.linalg.norm(table["codes"] - code, axis=1))
        ranked = [names[i] for i in order[:3]]
        hits1 += ranked[0] == style
        hits3 += style in ranked
    table["val_clips"] = len(val)
    table["val_top1"] = hits1 / len(val) if val else None
    table["val_top3"] = hits3 / len(val) if val else None
    return table


# --------------------------------------------------------------------------- main


def load_checkpoint_copy(path: Path) -> tuple[Translator, Fe.FeatureStats, dict]:
    """The generator, statistics and metadata of a COPY of ``path`` (``metrics`` and the
    checkpoint's modification time added to the metadata)."""
    from training.translator.train import load_translator

    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "translator.pt"
        shutil.copy2(path, copy)
        g, stats, meta = load_translator(copy)
        ckpt = torch.load(copy, map_location="cpu", weights_only=False)
        meta["metrics"] = ckpt.get("metrics") or {}
        meta["mtime"] = copy.stat().st_mtime
    return g, stats, meta


def main(argv: list[str] | None = None) -> dict:
    from training import data as D
    from training.translator.train import DEFAULT_CHECKPOINT

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", type=Path, default=DEFAULT_CHECKPOINT)
    p.add_argument("--models-dir", type=Path, default=MF.MODELS_DIR)
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)

    g, stats, meta = load_checkpoint_copy(args.checkpoint)
    step = int(meta["step"])
    models_dir = Path(args.models_dir)
    out = models_dir / FOLDER
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)

    paths = export_graphs(g, out)
    parity_figures = parity(g, paths)
    for graph, fig in parity_figures.items():
        print(f"{graph}: parity max abs {fig['max_abs']:.2e}, max rel {fig['max_rel']:.2e}")

    Fe.save_stats(out / "stats.npz", stats)
    clips = D.load_bandai(datasets=tuple(meta["train_config"]["datasets"]))
    table = style_table(g.style3d, stats, clips, meta["styles"], meta["val_takes"])
    np.savez(
        out / "styles.npz",
        names=np.array(table["names"]),
        codes=table["codes"],
        clips=table["clips"],
        velocity=table["velocity"],
        speed=table["speed"],
    )
    split = {"val_takes": list(meta["val_takes"]), "styles": list(meta["styles"]), "step": step}
    (out / "split.json").write_text(json.dumps(split, indent=1) + "\n")
    print(
        f"style table: {len(table['names'])} styles; held-out clips nearest style top-1 "
        f"{table['val_top1']:.3f}, top-3 {table['val_top3']:.3f} ({table['val_clips']} clips)"
    )

    io = graph_io(g)
    files = [f"{FOLDER}/{p.name}" for p in paths.values()]
    files += [f"{FOLDER}/stats.npz", f"{FOLDER}/styles.npz", f"{FOLDER}/split.json"]
    graphs = {
        graph: MF.graph_spec(f"{FOLDER}/{paths[graph].name}", OPSET, *io[graph])
        for graph in GRAPH_NAMES
    }
    cfg = g.cfg
    styles = {
        name: {
            "clips": int(table["clips"][i]),
            "velocity_factor": round(float(table["velocity"][i]), 4),
            "speed": round(float(table["speed"][i]), 4),
            "code": [round(float(v), 6) for v in table["codes"][i]],
        }
        for i, name in enumerate(table["names"])
    }
    metrics = {k: round(float(v), 5) for k, v in meta["metrics"].items()}
    metrics |= {
        "val_clip_style_top1": round(table["val_top1"], 4),
        "val_clip_style_top3": round(table["val_top3"], 4),
        "val_clips": table["val_clips"],
        "parity": parity_figures,
        "parity_lengths": list(PARITY_LENGTHS),
        "parity_batches": list(PARITY_BATCHES),
        "parity_rtol": RTOL,
        "parity_atol": ATOL,
    }
    trained_at = dt.datetime.fromtimestamp(meta["mtime"], dt.UTC).isoformat(timespec="seconds")
    entry = {
        "name": MODEL_NAME,
        "family": "translator",
        "version": f"0.1.{step}",
        "files": files,
        "graphs": graphs,
        "training_data": TRAINING_DATA,
        "licence": LICENCE,
        "trained_at": trained_at,
        "metrics": metrics,
        "extra": {
            "paper": "aberman2020 unpaired motion style transfer from video",
            "step": step,
            "stats": f"{FOLDER}/stats.npz",
            "styles_file": f"{FOLDER}/styles.npz",
            "split": f"{FOLDER}/split.json",
            "validation_takes": len(meta["val_takes"]),
            "stride": STRIDE,
            "receptive_field": receptive_field(cfg),
            "window": int(meta["train_config"]["window"]),
            "fps": Fe.FPS,
            "style_dim": cfg.style_dim,
            "code_channels": cfg.content_channels[-1],
            "model_config": cfg.to_dict(),
            "styles": styles,
        },
    }
    MF.put_entry(entry, models_dir)
    sizes = {p.name: p.stat().st_size for p in paths.values()}
    print(f"manifest: {MODEL_NAME} {entry['version']}, graphs {sizes} bytes", flush=True)
    return entry


if __name__ == "__main__":
    main()

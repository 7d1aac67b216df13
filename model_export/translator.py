"""Export the translator (``training.translator.networks``) to ONNX, with its statistics and
style table.

    python -m model_export.translator [--checkpoint checkpoints/translator.pt] [--models-dir models]

Writes ``models/translator/``:

- three single-file graphs with symbolic ``batch`` and ``time`` axes, ``(B, C, T)``:
  ``style3d.onnx`` (``motion3d (B, 63, time) -> style_code (B, S)``), ``style2d.onnx``
  (``motion2d (B, 32, time) -> style_code``) and ``restyler.onnx`` (``content (B, 193,
  time)``, ``style_code`` -> ``output (B, 126, time)``), each checked against torch at
  :data:`PARITY_LENGTHS` x :data:`PARITY_BATCHES` (rtol :data:`RTOL`, atol :data:`ATOL`);
- ``stats.npz``: the checkpoint's feature statistics (``motion.features.save_stats``);
- ``styles.npz``: per style (``names``) its named code (``codes``, trained with the
  networks), the count of its Bandai takes (``clips``), their mean velocity factor
  (``velocity``) and the style's ``speed`` against the other styles on the same actions
  (:func:`style_speeds`), a named style's time warp;

and the manifest entry ``translator-bandai`` (``model_export.manifest.put_entry``), with the
output smoothing ``model_export.output_smoothing`` measures for the new graphs before the
entry is written (Bandai's held-out takes: the export needs the shared data).
The checkpoint is read from a copy (a running training overwrites it).
"""

from __future__ import annotations

import argparse
import datetime as dt
import shutil
import tempfile
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from model_export import manifest as MF
from model_export import output_smoothing
from motion import features as Fe
from motion.styles import exaggerated
from training.translator.networks import RESTYLER_IN, NetworkConfig, Translator

OPSET = 17
MODEL_NAME = "translator-bandai"
FOLDER = "translator"
PARITY_LENGTHS = (31, 64, 99, 256)
PARITY_BATCHES = (1, 3)
RTOL, ATOL = 1e-4, 5e-5
TRAINING_DATA = [
    "Bandai-Namco-Research-Motiondataset 1 and 2 (CC BY-NC 4.0)",
    "Dance with Melody (Tang et al. 2018; research only), as unstyled motion",
]
LICENCE = (
    "research and evaluation only: trained on Bandai Namco Research Motion dataset, CC BY-NC 4.0"
)
GRAPH_NAMES = ("style3d", "style2d", "restyler")
# A named style's code is taken this far from the centre of the named codes, along the line
# through it (the engine's code_of_name); active and exhausted, one actor's and confused
# with each other, further. Chosen on the foreign evaluation's development half
# (docs/experiments/translator_constants.md has the figures).
NAMED_STYLE_GAIN = 1.75
NAMED_STYLE_GAINS = {"active": 2.0, "exhausted": 2.0}
# A style clip's code is taken this far from the centre of the learned codes (the engine's
# ``played``): the encoder's code of one take lies nearer the centre than its style's.
CLIP_STYLE_GAIN = 1.75
# A video's code likewise.
VIDEO_STYLE_GAIN = 1.75


def graph_io(net: Translator) -> dict[str, tuple[list, list]]:
    """Per graph ``(inputs, outputs)`` as ``(name, shape)`` pairs (symbolic dims as names)."""
    style = [("style_code", ["batch", net.cfg.style_dim])]
    return {
        "style3d": ([("motion3d", ["batch", Fe.STYLE3D_CHANNELS, "time"])], style),
        "style2d": ([("motion2d", ["batch", Fe.STYLE2D_CHANNELS, "time"])], style),
        "restyler": (
            [("content", ["batch", RESTYLER_IN, "time"]), *style],
            [("output", ["batch", Fe.OUTPUT_CHANNELS, "time"])],
        ),
    }


def example_inputs(net: Translator, graph: str, batch: int, frames: int, gen=None) -> tuple:
    def randn(*shape):
        return torch.randn(*shape, generator=gen)

    if graph == "style3d":
        return (randn(batch, Fe.STYLE3D_CHANNELS, frames),)
    if graph == "style2d":
        return (randn(batch, Fe.STYLE2D_CHANNELS, frames),)
    with torch.no_grad():
        code = net.style3d(randn(batch, Fe.STYLE3D_CHANNELS, frames))
    return randn(batch, RESTYLER_IN, frames), code


def export_graphs(net: Translator, out_dir: Path) -> dict[str, Path]:
    """The graphs of ``net`` as ``out_dir/<graph>.onnx`` (single files, symbolic axes)."""
    net.eval()
    out_dir.mkdir(parents=True, exist_ok=True)
    io = graph_io(net)
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
                getattr(net, graph),
                example_inputs(net, graph, 1, 64),
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
    net: Translator,
    paths: dict[str, Path],
    lengths: Iterable[int] = PARITY_LENGTHS,
    batches: Iterable[int] = PARITY_BATCHES,
    rtol: float = RTOL,
    atol: float = ATOL,
    seed: int = 0,
) -> dict[str, dict[str, float]]:
    """Torch against onnxruntime for every graph at every length and batch: ``{graph:
    {"max_abs", "max_rel"}}``; ``RuntimeError`` when an element is outside rtol/atol."""
    import onnxruntime as ort

    gen = torch.Generator().manual_seed(seed)
    net.eval()
    out: dict[str, dict[str, float]] = {}
    for graph, path in paths.items():
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        names = [i.name for i in session.get_inputs()]
        worst_abs = worst_rel = 0.0
        for frames in lengths:
            for batch in batches:
                x = example_inputs(net, graph, batch, frames, gen)
                with torch.no_grad():
                    want = getattr(net, graph)(*x).numpy()
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
    """3D style code ``(S,)`` of a whole clip's raw style3d features ``(F, 63)``."""
    x = torch.from_numpy(np.ascontiguousarray(Fe.standardize(style3d, stats, "style3d").T[None]))
    with torch.no_grad():
        return style3d_net(x).numpy()[0]


def style_speeds(velocity: dict[tuple[str, str], list[float]]) -> dict[str, float]:
    """How fast each style moves against the others *on the same action*: per action, the
    log of a style's mean velocity factor minus the mean of that over the action's styles;
    a style's speed is the exp of its mean over its actions (an action with one style says
    nothing; a style with none gets 1). A style's plain mean velocity factor would mix its
    actions (runs are fast, bows slow). ``velocity``: ``(action, style) -> factors``."""
    logs = {k: float(np.log(np.mean(v))) for k, v in velocity.items() if np.mean(v) > 1e-6}
    by_action: dict[str, dict[str, float]] = {}
    for (action, style), value in logs.items():
        by_action.setdefault(action, {})[style] = value
    offsets: dict[str, list[float]] = {}
    for per_style in by_action.values():
        if len(per_style) < 2:
            continue
        mean = float(np.mean(list(per_style.values())))
        for style, value in per_style.items():
            offsets.setdefault(style, []).append(value - mean)
    styles = {style for _, style in velocity}
    return {s: float(np.exp(np.mean(offsets[s]))) if s in offsets else 1.0 for s in styles}


def style_table(net: Translator, stats: Fe.FeatureStats, clips: list, styles: list[str]) -> dict:
    """Per (merged) style: its named code (trained with the networks), the count of its
    takes among ``clips`` (``training.data.Clip`` with ``style``, ``content`` and
    ``motion``), their mean velocity factor and the style's speed; and how often a take's
    own 3D code lies nearest its style's named code (``nearest_top1``)."""
    from motion.styles import canonical_style

    codes: dict[str, list[np.ndarray]] = {s: [] for s in styles}
    velocity: dict[str, list[float]] = {s: [] for s in styles}
    by_action: dict[tuple[str, str], list[float]] = {}
    for clip in clips:
        style = clip.style if clip.style in codes else canonical_style(clip.style)
        enc = Fe.encode(clip.motion)
        codes[style].append(clip_code(net.style3d, enc.style3d, stats))
        velocity[style].append(Fe.encoded_velocity_factor(enc))
        by_action.setdefault((clip.content, style), []).append(velocity[style][-1])
    speeds = style_speeds(by_action)
    named = net.named.weight.detach().numpy().astype(np.float32)
    hits = [
        int(np.argmin(np.linalg.norm(named - code, axis=1))) == k
        for k, s in enumerate(styles)
        for code in codes[s]
    ]
    return {
        "names": list(styles),
        "codes": named,
        "nearest_top1": np.array(np.mean(hits)),
        "clips": np.array([len(codes[s]) for s in styles], dtype=np.int64),
        "velocity": np.array([np.mean(velocity[s]) for s in styles], dtype=np.float64),
        "speed": np.array([speeds[s] for s in styles], dtype=np.float64),
    }


# --------------------------------------------------------------------------- main


def load_checkpoint(path: Path) -> tuple[Translator, Fe.FeatureStats, dict]:
    """The networks, statistics and saved metadata of a copy of ``path``."""
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "translator.pt"
        shutil.copy2(path, copy)
        payload = torch.load(copy, map_location="cpu", weights_only=False)
        payload["mtime"] = copy.stat().st_mtime
    net = Translator(NetworkConfig(**payload["network"]))
    net.load_state_dict(payload["weights"])
    net.eval()
    arrays = {k: v.numpy() for k, v in payload["stats"].items()}
    kinds = [k.removesuffix("_mean") for k in arrays if k.endswith("_mean")]
    stats = Fe.FeatureStats({k: arrays[f"{k}_mean"] for k in kinds},
                            {k: arrays[f"{k}_std"] for k in kinds})  # fmt: skip
    return net, stats, payload


def main(argv: list[str] | None = None) -> dict:
    from training import data as D
    from training.translator.fit import REPO

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", type=Path, default=REPO / "checkpoints" / "translator.pt")
    p.add_argument("--models-dir", type=Path, default=MF.MODELS_DIR)
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    return export(args.checkpoint, Path(args.models_dir), D.load_bandai())


def export(
    checkpoint: Path,
    models_dir: Path,
    clips: list,
    name: str = MODEL_NAME,
    training_data: list[str] = TRAINING_DATA,
    licence: str = LICENCE,
    extra: dict | None = None,
    measure_smoothing: bool = True,
    gains: dict[str, float] = NAMED_STYLE_GAINS,
) -> dict:
    """The translator of ``checkpoint`` in ``models_dir`` (module docstring) as the manifest
    entry ``name``, its style table from ``clips`` (the library it trained on); ``extra``
    joins the entry's. Without ``measure_smoothing`` the output smoothing is the largest
    candidate (it is measured on Bandai's held-out takes). ``gains``: named styles taken
    further than :data:`NAMED_STYLE_GAIN` (chosen for Bandai's)."""
    net, stats, payload = load_checkpoint(checkpoint)
    step = int(payload["step"])
    out = models_dir / FOLDER
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)

    paths = export_graphs(net, out)
    parity_figures = parity(net, paths)
    for graph, fig in parity_figures.items():
        print(f"{graph}: parity max abs {fig['max_abs']:.2e}, max rel {fig['max_rel']:.2e}")

    Fe.save_stats(out / "stats.npz", stats)
    table = style_table(net, stats, clips, payload["styles"])
    print(f"a take's own code is nearest its style's: {float(table['nearest_top1']):.1%}")
    np.savez(out / "styles.npz", **{k: np.asarray(v) for k, v in table.items()})

    io = graph_io(net)
    files = [f"{FOLDER}/{p.name}" for p in paths.values()]
    files += [f"{FOLDER}/stats.npz", f"{FOLDER}/styles.npz"]
    graphs = {
        graph: MF.graph_spec(f"{FOLDER}/{paths[graph].name}", OPSET, *io[graph])
        for graph in GRAPH_NAMES
    }
    names = [str(n) for n in table["names"]]
    gains = {style: gains.get(style, NAMED_STYLE_GAIN) for style in names}
    used = exaggerated(table["codes"], np.array([gains[name] for name in names]))
    styles = {  # "code": what the name uses (the engine's code_of_name)
        name: {
            "clips": int(table["clips"][i]),
            "velocity_factor": round(float(table["velocity"][i]), 4),
            "speed": round(float(table["speed"][i]), 4),
            "code": [round(float(v), 6) for v in used[i]],
        }
        for i, name in enumerate(names)
    }
    trained_at = dt.datetime.fromtimestamp(payload["mtime"], dt.UTC).isoformat(timespec="seconds")
    entry = {
        "name": name,
        "family": "translator",
        "version": MF.dated_version(name, models_dir),
        "files": files,
        "graphs": graphs,
        "training_data": list(training_data),
        "licence": licence,
        "trained_at": trained_at,
        "metrics": {
            "takes_nearest_own_style": round(float(table["nearest_top1"]), 4),
            "parity": parity_figures,
            "parity_lengths": list(PARITY_LENGTHS),
            "parity_batches": list(PARITY_BATCHES),
            "parity_rtol": RTOL,
            "parity_atol": ATOL,
        },
        "extra": {
            "paper": "aberman2020 (style codes from clips and video), trained on aligned pairs",
            "step": step,
            "schedule_stages": list(payload.get("stages", [])),
            "stats": f"{FOLDER}/stats.npz",
            "styles_file": f"{FOLDER}/styles.npz",
            "window": int(payload["train"]["window"]),
            "receptive_field": net.cfg.receptive_field,
            "fps": Fe.FPS,
            "style_dim": net.cfg.style_dim,
            "network": net.cfg.to_dict(),
            "aliases": dict(payload["aliases"]),
            "named_style_gains": gains,
            "clip_style_gain": CLIP_STYLE_GAIN,
            "video_style_gain": VIDEO_STYLE_GAIN,
            "styles": styles,
            "output_smoothing": max(output_smoothing.CANDIDATES),  # unless measured below
        }
        | (extra or {}),
    }
    if payload.get("validation"):
        entry["metrics"]["validation"] = payload["validation"]
    if measure_smoothing:
        output_smoothing.measured("translator", entry, models_dir)
    MF.put_entry(entry, models_dir)
    sizes = {p.name: p.stat().st_size for p in paths.values()}
    print(f"manifest: {name} {entry['version']}, graphs {sizes} bytes", flush=True)
    return entry


if __name__ == "__main__":
    main()

"""Export the fast style networks (holden2017) to ONNX and list them in the manifest.

    python -m model_export.fast [--checkpoint-dir checkpoints/fast] [--models-dir models]

Writes ``models/fast/projection.onnx`` (the loss network as manifold projection,
``motion (batch, time, 70) -> projected``), ``models/fast/style_<name>.onnx`` per trained
style (``motion -> styled``), ``models/fast/stats.npz`` (feature statistics), and one
manifest entry ``fast-bandai`` with every graph, each style's speed and the style names'
aliases taken from the shipped translator (the networks' teacher, ``training.fast_style``).
Each graph is checked against torch at several lengths and batch sizes (``PARITY_SHAPES``,
rtol 1e-4) before it is listed.

The TorchScript exporter is used: torch.export specialises the time axis of the
projection (its odd-length pooling and crop), the TorchScript one keeps it symbolic.
"""

from __future__ import annotations

import argparse
import shutil
import warnings
from pathlib import Path

import numpy as np
import torch

from model_export import manifest as MF
from motion import fast_features as FF
from training import fast_common as FC
from training.fast_style import load_autoencoder

OPSET = 17
PARITY_SHAPES = [(b, t) for t in (32, 100, 241) for b in (1, 3)]
RTOL, ATOL = 1e-4, 1e-5
MODEL_NAME = "fast-bandai"
FOLDER = "fast"
TRAINING_DATA = [
    "Bandai-Namco-Research-Motiondataset 1 and 2 (CC BY-NC 4.0)",
    "CMU Graphics Lab Motion Capture Database, dance takes (CMU terms)",
    "Dance with Melody (research only, no licence stated)",
]
LICENCE = "research and evaluation only (trained on Bandai CC BY-NC 4.0, CMU, Dance with Melody)"


def export_graph(module: torch.nn.Module, path: Path, output: str) -> None:
    """``module`` (``motion (B, T, C)`` -> ``(B, T, C)``) to a single-file ONNX graph with
    symbolic batch and time axes."""
    module.eval()
    dims = {0: "batch", 1: "time"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            (torch.zeros(1, 64, FF.CHANNELS),),
            str(path),
            dynamo=False,
            opset_version=OPSET,
            input_names=["motion"],
            output_names=[output],
            dynamic_axes={"motion": dims, output: dims},
        )
    check_symbolic(path)


def check_symbolic(path: Path) -> None:
    """Every input and output has symbolic batch and time dims and the fixed channel count."""
    import onnx

    model = onnx.load(str(path))
    onnx.checker.check_model(model)
    for value in list(model.graph.input) + list(model.graph.output):
        dims = [d.dim_param or d.dim_value for d in value.type.tensor_type.shape.dim]
        if dims != ["batch", "time", FF.CHANNELS]:
            raise RuntimeError(f"{path.name}: {value.name} has shape {dims}")


def parity(module: torch.nn.Module, path: Path, seed: int = 0) -> float:
    """Largest absolute difference torch vs onnxruntime over :data:`PARITY_SHAPES`;
    raises when any element is outside ``rtol=1e-4, atol=1e-5``."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    gen = torch.Generator().manual_seed(seed)
    worst = 0.0
    for batch, frames in PARITY_SHAPES:
        x = torch.randn(batch, frames, FF.CHANNELS, generator=gen)
        with torch.no_grad():
            want = module(x).numpy()
        got = session.run(None, {"motion": x.numpy()})[0]
        if got.shape != want.shape or not np.allclose(got, want, rtol=RTOL, atol=ATOL):
            raise RuntimeError(f"{path.name}: parity fails at batch {batch}, time {frames}")
        worst = max(worst, float(np.abs(got - want).max()))
    return worst


def translator_entry(models_dir: Path):
    """The shipped translator's manifest entry: the teacher the styles were distilled from,
    whose style speeds and other names they share."""
    from service.manifest import load_manifest

    return next(m for m in load_manifest(models_dir).models if m.family == "translator")


def load_style(path: Path) -> tuple[FC.StyleNet, dict]:
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    net = FC.StyleNet(hidden=ckpt["config"]["hidden"], width=ckpt["config"]["width"])
    net.load_state_dict(ckpt["model"])
    return net.eval(), ckpt


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint-dir", default=str(FC.CHECKPOINTS))
    p.add_argument("--models-dir", default=str(MF.MODELS_DIR))
    p.add_argument("--styles", nargs="*", help="only these (default: every checkpoint)")
    args = p.parse_args(argv)
    ckpt_dir, models_dir = Path(args.checkpoint_dir), Path(args.models_dir)
    out = models_dir / FOLDER
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)

    ae_ckpt = torch.load(ckpt_dir / "autoencoder.pt", map_location="cpu", weights_only=False)
    ae = load_autoencoder(ckpt_dir / "autoencoder.pt")
    projection = FC.Projection(ae).eval()
    shutil.copyfile(ckpt_dir / "stats.npz", out / "stats.npz")
    teacher = translator_entry(models_dir)
    speeds = {name: info["speed"] for name, info in teacher.extra["styles"].items()}

    shape = ["batch", "time", FF.CHANNELS]
    files = [f"{FOLDER}/stats.npz"]
    graphs = {}
    parity_max: dict[str, float] = {}
    export_graph(projection, out / "projection.onnx", "projected")
    parity_max["projection"] = parity(projection, out / "projection.onnx")
    files.append(f"{FOLDER}/projection.onnx")
    graphs["projection"] = MF.graph_spec(
        f"{FOLDER}/projection.onnx", OPSET, [("motion", shape)], [("projected", shape)]
    )

    styles = {}
    paths = sorted(ckpt_dir.glob("style_*.pt"))
    for path in paths:
        name = path.stem.removeprefix("style_")
        if args.styles and name not in args.styles:
            continue
        net, ckpt = load_style(path)
        graph = f"style_{name}"
        file = f"{FOLDER}/{graph}.onnx"
        export_graph(net, models_dir / file, "styled")
        parity_max[graph] = parity(net, models_dir / file)
        files.append(file)
        graphs[graph] = MF.graph_spec(file, OPSET, [("motion", shape)], [("styled", shape)])
        result = ckpt["result"]
        styles[name] = {
            "graph": graph,
            "clips": teacher.extra["styles"][name]["clips"],
            "speed": speeds[name],
            "steps": result["steps"],
            "train_loss": result["train"],
            "trained_at": result.get("trained_at"),
        }
        print(f"exported {graph}: parity max abs {parity_max[graph]:.2e}", flush=True)

    ae_result = ae_ckpt["result"]
    entry = {
        "name": MODEL_NAME,
        "family": "fast",
        "version": MF.dated_version(MODEL_NAME, models_dir),
        "files": files,
        "graphs": graphs,
        "training_data": TRAINING_DATA,
        "licence": LICENCE,
        "trained_at": max([ae_result["trained_at"]] + [s["trained_at"] or "" for s in styles.values()]),
        "metrics": {
            "autoencoder_val_mse": round(ae_result["val_mse"], 6),
            "autoencoder_train_mse": round(ae_result["train_mse"], 6),
            "parity_max_abs": parity_max,
            "parity_shapes": [list(s) for s in PARITY_SHAPES],
            "parity_rtol": RTOL,
        },
        "extra": {
            "paper": "holden2017 fast neural style transfer for motion, distilled from the "
                     "translator",
            "teacher": f"{teacher.name} {teacher.version}",
            "aliases": dict(teacher.extra.get("aliases", {})),
            "stats": f"{FOLDER}/stats.npz",
            "channels": FF.CHANNELS,
            "fps": FF.FPS,
            "window": FC.WINDOW,
            "autoencoder": {"hidden": ae.conv.out_channels, "width": FC.WIDTH,
                            "steps": ae_result["step"]},
            "styles": styles,
        },
    }  # fmt: skip
    MF.put_entry(entry, models_dir)
    print(f"manifest: {MODEL_NAME} with {len(styles)} styles, {len(files)} files", flush=True)
    return entry


if __name__ == "__main__":
    main()

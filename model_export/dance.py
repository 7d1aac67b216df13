"""Export the dance network (jacob2019, made to work) to ONNX and list it in the manifest.

    python -m model_export.dance [--checkpoint checkpoints/dance.pt] [--models-dir models]

Three graphs, each with a symbolic batch axis:

- ``audio``: ``audio (batch, time, 97)`` standardised song features -> ``code (batch, time,
  128)`` and ``genre_probs (batch, 4)`` (the classifier head over the music genres);
- ``step``: one frame of generation with the LSTM states explicit, ``code (batch, 128)``,
  ``genre (batch, 7)`` (one-hot or probabilities), ``prev (batch, 134)`` standardised pose,
  ``h1, c1, h2, c2 (batch, hidden)`` -> ``pose (batch, 134)`` and ``h1_out .. c2_out``;
- ``step_float``: the same step with float weights.

The step graph ships with 8-bit weights (onnxruntime's dynamic quantisation, a scale per
output channel): a whole song runs it once a frame, and it is bound by reading its weights,
so 8 bits halve the generation loop (docs/dance_alignment.md, rule 21; docs/quantization.md).

Writes ``models/dance/{audio,step,step_float}.onnx``, ``models/dance/step_check.npz`` (steps
of the network the engine checks the 8-bit graph against on its CPU, serving ``step_float``
where it fails), ``models/dance/stats.npz`` (feature statistics and the seeded start poses)
and the manifest entry ``dance-dwm``. Parity with torch is checked before listing: the audio
graph at several shapes, the step graph over ``PARITY_STEPS`` autoregressive steps, each fed
torch's pose and states of the step before, in float to ``ATOL`` and once quantised to
``INT8_ATOL``.
"""

from __future__ import annotations

import argparse
import shutil
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from model_export import manifest as MF
from motion import dance_features as DF
from service.engines.dance import STATES  # the step graph's state names, one contract
from training import dance as TD

OPSET = 17
MODEL_NAME = "dance-dwm"
FOLDER = "dance"
PARITY_STEPS = 100
RTOL, ATOL = 1e-4, 1e-4
INT8_ATOL = 0.15  # the shipped folds' 8-bit steps differ from torch by 0.04-0.05 (standardised)
AUDIO_SHAPES = [(1, 1), (1, 64), (2, 257)]
CHECK_STEPS = 16
BUNDLE_FILES = ("audio.onnx", "step.onnx", "step_float.onnx", "step_check.npz", "stats.npz")
TRAINING_DATA = [
    "Dance with Melody (Tang et al. 2018; research only, no licence stated; commercial music)",
    "CMU Graphics Lab Motion Capture Database, salsa / Indian / modern dance takes (CMU terms)",
]
LICENCE = "research and evaluation only (Dance with Melody has no licence; its music is commercial)"


class AudioGraph(nn.Module):
    def __init__(self, model: TD.DanceNet) -> None:
        super().__init__()
        self.model = model

    def forward(self, audio: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        code, logits = self.model.encode_audio(audio)
        return code, torch.softmax(logits, dim=-1)


class StepGraph(nn.Module):
    def __init__(self, model: TD.DanceNet) -> None:
        super().__init__()
        self.model = model

    def forward(self, code, genre, prev, h1, c1, h2, c2):
        return self.model.step(code, genre, prev, h1, c1, h2, c2)


def _export(module, args, path: Path, inputs, outputs, dynamic) -> None:
    module.eval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            args,
            str(path),
            dynamo=False,
            opset_version=OPSET,
            input_names=list(inputs),
            output_names=list(outputs),
            dynamic_axes=dynamic,
        )
    import onnx

    onnx.checker.check_model(onnx.load(str(path)))


def export_graphs(model: TD.DanceNet, out: Path) -> None:
    """``audio.onnx`` and ``step.onnx`` of ``model`` (eval mode) into folder ``out``."""
    model.eval()
    hidden, code = model.config.hidden, model.config.code
    _export(
        AudioGraph(model),
        (torch.zeros(1, 16, DF.AUDIO_CHANNELS),),
        out / "audio.onnx",
        ["audio"],
        ["code", "genre_probs"],
        {"audio": {0: "batch", 1: "time"}, "code": {0: "batch", 1: "time"},
         "genre_probs": {0: "batch"}},
    )  # fmt: skip
    step_inputs = ["code", "genre", "prev", *STATES]
    step_outputs = ["pose", *(f"{n}_out" for n in STATES)]
    zeros = torch.zeros(1, hidden)
    _export(
        StepGraph(model),
        (torch.zeros(1, code), torch.zeros(1, len(DF.GENRES)),
         torch.zeros(1, DF.MOTION_CHANNELS), zeros, zeros, zeros, zeros),
        out / "step.onnx",
        step_inputs,
        step_outputs,
        {name: {0: "batch"} for name in step_inputs + step_outputs},
    )  # fmt: skip


def graph_specs(model: TD.DanceNet) -> dict:
    hidden, code = model.config.hidden, model.config.code
    states = [(n, ["batch", hidden]) for n in STATES]
    return {
        "audio": MF.graph_spec(
            f"{FOLDER}/audio.onnx",
            OPSET,
            [("audio", ["batch", "time", DF.AUDIO_CHANNELS])],
            [("code", ["batch", "time", code]), ("genre_probs", ["batch", len(DF.MUSIC_GENRES)])],
        ),
        **{graph: MF.graph_spec(
            f"{FOLDER}/{graph}.onnx",
            OPSET,
            [("code", ["batch", code]), ("genre", ["batch", len(DF.GENRES)]),
             ("prev", ["batch", DF.MOTION_CHANNELS]), *states],
            [("pose", ["batch", DF.MOTION_CHANNELS]), *((f"{n}_out", s) for n, s in states)],
        ) for graph in ("step", "step_float")},
    }  # fmt: skip


def quantise_step(out: Path) -> None:
    """``out/step.onnx`` rewritten with 8-bit weights, a scale per output channel; its inputs
    are quantised per call, so the graph's inputs and outputs stay float. The weights are
    unsigned: with signed ones, onnxruntime's AVX2 kernel (a CPU without VNNI) saturates its
    16-bit sums, and the step differed from torch by 0.42 where VNNI gave 0.04-0.07."""
    import logging

    from onnxruntime.quantization import QuantType, quantize_dynamic

    path = str(out / "step.onnx")
    logging.disable(logging.WARNING)  # its advice to pre-process: the graph is judged as is
    try:
        quantize_dynamic(path, path, weight_type=QuantType.QUInt8, per_channel=True)
    finally:
        logging.disable(logging.NOTSET)


def parity(
    model: TD.DanceNet, out: Path, seed: int = 0, steps: int = PARITY_STEPS, int8: bool = False
) -> dict:
    """Largest absolute differences torch vs onnxruntime: the audio graph at
    :data:`AUDIO_SHAPES`, the step graph over ``steps`` autoregressive steps (batch 2), both
    fed torch's pose and states of the step before: a free-running loop amplifies the two
    runtimes' rounding (as it does the thread count's), and one network failed at step 76
    on a last-bit difference. Raises ``RuntimeError`` outside ``RTOL``/``ATOL`` (the step,
    when ``int8``, outside ``INT8_ATOL``)."""
    import onnxruntime as ort

    step_rtol, step_atol = (0.0, INT8_ATOL) if int8 else (RTOL, ATOL)

    model.eval()
    gen = torch.Generator().manual_seed(seed)
    audio = ort.InferenceSession(str(out / "audio.onnx"), providers=["CPUExecutionProvider"])
    worst_audio = 0.0
    for batch, frames in AUDIO_SHAPES:
        x = torch.randn(batch, frames, DF.AUDIO_CHANNELS, generator=gen)
        with torch.no_grad():
            want = [t.numpy() for t in AudioGraph(model)(x)]
        got = audio.run(None, {"audio": x.numpy()})
        for g, w in zip(got, want, strict=True):
            if g.shape != w.shape or not np.allclose(g, w, rtol=RTOL, atol=ATOL):
                raise RuntimeError(f"audio.onnx: parity fails at batch {batch}, time {frames}")
            worst_audio = max(worst_audio, float(np.abs(g - w).max()))

    step = ort.InferenceSession(str(out / "step.onnx"), providers=["CPUExecutionProvider"])
    worst_step = 0.0
    for t, (feeds, want) in enumerate(teacher_forced(model, steps, gen)):
        for g, w in zip(step.run(None, feeds), want, strict=True):
            if not np.allclose(g, w, rtol=step_rtol, atol=step_atol):
                raise RuntimeError(f"step.onnx: parity fails at step {t}")
            worst_step = max(worst_step, float(np.abs(g - w).max()))
    return {"audio": worst_audio, "step": worst_step, "steps": steps}


def teacher_forced(model: TD.DanceNet, steps: int, gen: torch.Generator):
    """The step graph's feeds and torch's outputs (pose, states) over ``steps`` steps of a
    batch of 2 random sequences, each step fed torch's pose and states of the step before."""
    batch = 2
    code = torch.randn(batch, steps, model.config.code, generator=gen).relu()
    genre = torch.softmax(torch.randn(batch, len(DF.GENRES), generator=gen), -1)
    prev_t = torch.randn(batch, DF.MOTION_CHANNELS, generator=gen)
    state_t = model.init_state(batch)
    for t in range(steps):
        feeds = {"code": code[:, t].numpy(), "genre": genre.numpy(), "prev": prev_t.numpy()}
        feeds.update({n: s.numpy() for n, s in zip(STATES, state_t, strict=True)})
        with torch.no_grad():
            prev_t, *state_t = model.step(code[:, t], genre, prev_t, *state_t)
        yield feeds, [w.numpy() for w in (prev_t, *state_t)]


def save_step_check(model: TD.DanceNet, path: Path, seed: int = 2) -> None:
    """``path`` (.npz): :data:`CHECK_STEPS` teacher-forced steps' feeds (``in_<input>``) and
    torch's outputs (``out_<output>``), each ``(steps, 2, C)``, and ``atol``: what the engine
    checks its 8-bit step graph against where it runs (a CPU's kernels decide its rounding)."""
    model.eval()
    steps = list(teacher_forced(model, CHECK_STEPS, torch.Generator().manual_seed(seed)))
    arrays = {f"in_{n}": np.stack([f[n] for f, _ in steps]) for n in steps[0][0]}
    for k, name in enumerate(["pose", *(f"{n}_out" for n in STATES)]):
        arrays[f"out_{name}"] = np.stack([w[k] for _, w in steps])
    np.savez(path, **arrays, atol=np.float32(INT8_ATOL))


def export_bundle(
    model: TD.DanceNet,
    stats: DF.DanceStats,
    start_poses: np.ndarray,
    models_dir: Path,
    *,
    metrics: dict | None = None,
    extra: dict | None = None,
    trained_at: str | None = None,
    name: str = MODEL_NAME,
) -> dict:
    """Graphs, statistics and the manifest entry of one dance bundle under ``models_dir``
    (replacing an entry of the same name). Returns the entry."""
    out = Path(models_dir) / FOLDER
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    export_graphs(model, out)
    checks = parity(model, out)
    shutil.copyfile(out / "step.onnx", out / "step_float.onnx")
    quantise_step(out)
    checks["step_int8"] = parity(model, out, int8=True)["step"]
    save_step_check(model, out / "step_check.npz")
    stats.save(out / "stats.npz", start_poses=np.asarray(start_poses, np.float32))
    entry = {
        "name": name,
        "family": "dance",
        "version": MF.dated_version(name, models_dir),
        "files": [f"{FOLDER}/{file}" for file in BUNDLE_FILES],
        "graphs": graph_specs(model),
        "training_data": TRAINING_DATA,
        "licence": LICENCE,
        "trained_at": trained_at,
        "metrics": {
            **(metrics or {}),
            "parity_max_abs": checks,
            "parity_rtol": RTOL,
            "parity_int8_atol": INT8_ATOL,
        },
        "extra": {
            "paper": "jacob2019 genre-based dance generation (audio -> FC -> 2 LSTM)",
            "stats": f"{FOLDER}/stats.npz",
            "step_check": f"{FOLDER}/step_check.npz",
            "genres": list(DF.GENRES),
            "music_genres": list(DF.MUSIC_GENRES),
            "hidden": model.config.hidden,
            "step_weights": "uint8, a scale per output channel (onnxruntime quantize_dynamic)",
            "fps": DF.FPS,
            "audio_channels": DF.AUDIO_CHANNELS,
            "motion_channels": DF.MOTION_CHANNELS,
            **(extra or {}),
        },
    }
    MF.put_entry(entry, Path(models_dir))
    return entry


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", type=Path, default=TD.CHECKPOINT)
    p.add_argument("--models-dir", type=Path, default=MF.MODELS_DIR)
    p.add_argument("--name", default=MODEL_NAME, help="the manifest entry's name")
    args = p.parse_args(argv)
    model, stats, ckpt = TD.load_checkpoint(args.checkpoint)
    from training.dance_alignment import load_table

    summary = load_table()["summary"]
    entry = export_bundle(
        model,
        stats,
        ckpt["start_poses"],
        args.models_dir,
        metrics={
            "steps": int(ckpt["step"]),
            "best_val": ckpt.get("best_val"),
            "stages": ckpt.get("stages", []),
            **({"stage_steps": ckpt["stage_steps"]} if "stage_steps" in ckpt else {}),
        },
        extra={
            "alignment": {
                "global_rate": summary["global_rate"],
                "verified": summary["verified"],
                "rate_corrected": summary["rate_corrected"],
            },
            "fold": TD.fold_of(ckpt),
            "validation_takes": list(TD.held_out_takes(ckpt)),
        },
        trained_at=ckpt.get("saved_at"),
        name=args.name,
    )
    print(f"manifest: {entry['name']} {entry['metrics']['parity_max_abs']}")
    return entry


if __name__ == "__main__":
    main()

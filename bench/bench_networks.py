"""Speed of the translator and dance networks: frames per second, network only, for 240, 960
and 3,840 frames, onnxruntime vs torch eager, measured in one run.

    python -m bench.bench_networks [--repeats 20] [--lengths 240 960 3840] [--json]

Translator, what a transfer runs: the restyler over the content's windows (half a window
apart) with a style code, and the same plus the 3D style encoder over the content (its own
code, padded to the engine's length bucket, ``service.engines.restyling.padded_length``);
frames/s counted on the clip's length. Dance (jacob2019 made to work): the audio network over the whole input (padded to
the engine's bucket of 256 frames) and the step network run autoregressively for every
frame (its own pose and LSTM states fed back, batch 1), and the two together (the sum of
their medians). Random standard-normal inputs: the speed does not depend on the values.

The same weights in both runtimes where they can be had: the shipped ONNX files
(``models/translator``, ``models/dance``) and, for torch, a copy of
``checkpoints/translator.pt`` / ``checkpoints/dance.pt`` (trainings overwrite them) when its
network sizes are those of the shipped graphs, else fresh networks of the shipped sizes.
A dance model not shipped yet: torch rows only, from the checkpoint; neither: skipped
with a line saying so. Threads: the service's intra-op setting for both runtimes.
``bench.bench_fast`` does the same for the fast networks. Needs torch (a training extra).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.bench_fast import timed
from motion import features as Fe

LENGTHS = (240, 960, 3840)
REPO = Path(__file__).resolve().parent.parent


def _checkpoint_copy(path: Path, load):
    """``load(copy)`` of a temporary copy of ``path`` (a training may be writing it)."""
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / path.name
        shutil.copy2(path, copy)
        return load(copy)


def _row(family: str, graph: str, frames: int, t_ort: float | None, t_torch: float) -> dict:
    return {
        "family": family,
        "graph": graph,
        "frames": frames,
        "ort_fps": frames / t_ort if t_ort else None,
        "torch_fps": frames / t_torch,
        "ort_over_torch": t_torch / t_ort if t_ort else None,
        "ort_ms": t_ort * 1000 if t_ort else None,
        "torch_ms": t_torch * 1000,
    }


# --------------------------------------------------------------------------- translator


def translator_rows(entry, settings, lengths, repeats: int, threads: int) -> tuple[list, dict]:
    """Rows for the translator networks, and where the torch weights came from."""
    import torch

    from model_export.translator import load_checkpoint
    from service.engines.base import create_session
    from service.engines.restyling import BUCKET, padded_length
    from training.translator.networks import NetworkConfig, Translator

    config = NetworkConfig(**entry.extra["network"])
    checkpoint = REPO / "checkpoints" / "translator.pt"
    weights = "fresh networks of the shipped sizes (no checkpoint)"
    net = None
    if checkpoint.exists():
        net, _, payload = load_checkpoint(checkpoint)
        if net.cfg.to_dict() == config.to_dict():
            weights = f"{checkpoint.relative_to(REPO)} (step {payload['step']})"
        else:
            net = None
            weights = "fresh networks of the shipped sizes (the checkpoint's sizes differ)"
    if net is None:
        torch.manual_seed(0)
        net = Translator(config).eval()
    sessions = {
        name: create_session(settings.models_dir[0] / entry.graphs[name].file, threads)
        for name in ("style3d", "restyler")
    }
    window = int(entry.extra["window"])
    minimum = int(entry.extra.get("receptive_field", BUCKET))
    rng = np.random.default_rng(0)
    rows = []
    for frames in lengths:
        count = max(1, -(-(frames - window) // (window // 2)) + 1)  # windows half a window apart
        padded = padded_length(frames, minimum)
        content = rng.standard_normal((count, Fe.CONTROL_CHANNELS, window)).astype(np.float32)
        motion3d = rng.standard_normal((1, Fe.STYLE3D_CHANNELS, padded)).astype(np.float32)
        codes = rng.standard_normal((count, config.style_dim)).astype(np.float32)
        content_t, motion3d_t, codes_t = (torch.from_numpy(a) for a in (content, motion3d, codes))

        def ort_restyle(content=content, codes=codes):
            return sessions["restyler"].run(None, {"content": content, "style_code": codes})[0]

        def ort_transfer(content=content, motion3d=motion3d, codes=codes):
            sessions["style3d"].run(None, {"motion3d": motion3d})
            return ort_restyle(content, codes)

        def torch_restyle(content=content_t, codes=codes_t):
            with torch.inference_mode():
                return net.restyler(content, codes)

        def torch_transfer(content=content_t, motion3d=motion3d_t, codes=codes_t):
            with torch.inference_mode():
                net.style3d(motion3d)
                return net.restyler(content, codes)

        for what, ort_fn, torch_fn in (
            (f"restyler ({count} windows)", ort_restyle, torch_restyle),
            ("+ style3d of the content (a transfer)", ort_transfer, torch_transfer),
        ):
            t_ort = timed(ort_fn, repeats)
            t_torch = timed(torch_fn, repeats)
            row = _row("translator", what, frames, t_ort, t_torch)
            row["padded_frames"] = padded
            rows.append(row)
    return rows, {"torch_weights": weights, "onnx": f"{entry.name}/{entry.version}"}


# --------------------------------------------------------------------------- dance


def dance_rows(entry, settings, lengths, repeats: int, threads: int) -> tuple[list, dict]:
    """Rows for the dance networks (ONNX ones only when ``entry`` is not None), and where the
    weights came from."""
    import torch

    from motion import dance_features as DF
    from service.engines.base import create_session
    from service.engines.dance import BUCKET
    from training import dance as TD

    model = None
    weights = "fresh networks of the shipped sizes (no checkpoint)"
    if TD.CHECKPOINT.exists():
        model, _, ckpt = _checkpoint_copy(TD.CHECKPOINT, TD.load_checkpoint)
        weights = f"{TD.CHECKPOINT.relative_to(REPO)} (step {ckpt.get('step')})"
    sessions = None
    if entry is not None:
        sessions = {
            name: create_session(settings.models_dir[0] / entry.graphs[name].file, threads)
            for name in ("audio", "step")
        }
        code_dim = int(dict((t.name, t.shape) for t in entry.graphs["step"].inputs)["code"][1])
        hidden = int(entry.extra["hidden"])
        if model is not None and (model.config.hidden, model.config.code) != (hidden, code_dim):
            model = None
            weights = "fresh networks of the shipped sizes (the checkpoint's sizes differ)"
        if model is None:
            torch.manual_seed(0)
            model = TD.DanceNet(TD.Config(hidden=hidden, code=code_dim)).eval()
    hidden, code_dim = model.config.hidden, model.config.code
    genres = len(DF.GENRES)
    rng = np.random.default_rng(0)
    rows = []
    for frames in lengths:
        padded = max(BUCKET, -(-frames // BUCKET) * BUCKET)
        audio = rng.standard_normal((1, padded, DF.AUDIO_CHANNELS)).astype(np.float32)
        code = np.maximum(rng.standard_normal((frames, code_dim)), 0).astype(np.float32)
        genre = np.eye(genres, dtype=np.float32)[:1]
        start = rng.standard_normal((1, DF.MOTION_CHANNELS)).astype(np.float32)
        audio_t, code_t, genre_t, start_t = (
            torch.from_numpy(a) for a in (audio, code, genre, start)
        )

        def ort_audio(audio=audio):
            return sessions["audio"].run(None, {"audio": audio})

        def ort_steps(code=code, genre=genre, start=start):
            zeros = np.zeros((1, hidden), np.float32)
            feeds = {"genre": genre, "h1": zeros, "c1": zeros, "h2": zeros, "c2": zeros}
            prev = start
            step = sessions["step"]
            for t in range(1, len(code)):
                feeds["code"] = code[t : t + 1]
                feeds["prev"] = prev
                prev, feeds["h1"], feeds["c1"], feeds["h2"], feeds["c2"] = step.run(None, feeds)
            return prev

        def torch_audio(audio=audio_t):
            with torch.inference_mode():
                code, logits = model.encode_audio(audio)
                return code, torch.softmax(logits, dim=-1)

        def torch_steps(code=code_t, genre=genre_t, start=start_t):
            with torch.inference_mode():
                state = model.init_state(1)
                prev = start
                for t in range(1, len(code)):
                    prev, *state = model.step(code[t : t + 1], genre, prev, *state)
                return prev

        times = {}
        for what, ort_fn, torch_fn in (
            ("audio network (whole input)", ort_audio, torch_audio),
            ("step network (every frame)", ort_steps, torch_steps),
        ):
            t_ort = timed(ort_fn, repeats) if sessions else None
            t_torch = timed(torch_fn, repeats)
            times[what] = (t_ort, t_torch)
            row = _row("dance", what, frames, t_ort, t_torch)
            row["padded_frames"] = padded if what.startswith("audio") else frames
            rows.append(row)
        t_ort = sum(t for t, _ in times.values()) if sessions else None
        t_torch = sum(t for _, t in times.values())
        rows.append(_row("dance", "audio + steps (a dance; sum)", frames, t_ort, t_torch))
    info = {"torch_weights": weights, "onnx": f"{entry.name}/{entry.version}" if entry else None}
    return rows, info


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> dict:
    import torch

    from service.config import Settings, available_cpus
    from service.manifest import load_manifest
    from training import dance as TD

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--lengths", type=int, nargs="+", default=list(LENGTHS), help="frames")
    p.add_argument("--families", nargs="+", default=["translator", "dance"],
                   choices=["translator", "dance"])  # fmt: skip
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if args.repeats < 1 or any(n < 2 for n in args.lengths):
        p.error("--repeats must be >= 1 and --lengths >= 2")
    note = sys.stderr if args.json else sys.stdout  # keep --json output pure JSON

    settings = Settings()
    manifest = load_manifest(settings.models_dir[0])
    entries = {m.family: m for m in manifest.models}
    threads = settings.intra_op_threads
    torch.set_num_threads(threads)

    rows: list[dict] = []
    sources: dict[str, dict] = {}
    skipped: dict[str, str] = {}
    if "translator" in args.families:
        if "translator" in entries:
            found, sources["translator"] = translator_rows(
                entries["translator"], settings, args.lengths, args.repeats, threads
            )
            rows += found
        else:
            skipped["translator"] = f"no translator model in {settings.models_dir[0]}/manifest.json"
    if "dance" in args.families:
        entry = entries.get("dance")
        if entry is None and not TD.CHECKPOINT.exists():
            skipped["dance"] = (
                f"no dance model in {settings.models_dir[0]}/manifest.json and no {TD.CHECKPOINT}"
            )
        else:
            if entry is None:
                print(
                    f"dance: no model in {settings.models_dir[0]}/manifest.json yet: torch only",
                    file=note,
                )
            found, sources["dance"] = dance_rows(
                entry, settings, args.lengths, args.repeats, threads
            )
            rows += found
    for family, why in skipped.items():
        print(f"{family}: skipped, {why}", file=note)

    result = {
        "threads": threads,
        "cores": available_cpus(),
        "torch": torch.__version__,
        "repeats": args.repeats,
        "sources": sources,
        "skipped": skipped,
        "rows": rows,
        "paper_fps_jacob2019_t4": 1175,
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(f"{threads} threads ({available_cpus()} cores), torch {torch.__version__}")
        for family, info in sources.items():
            print(
                f"  {family}: onnx {info['onnx'] or '(not shipped)'}, torch {info['torch_weights']}"
            )
        print(
            "\n| family | graph | frames | onnxruntime frames/s | torch eager frames/s | ort / torch |"
        )
        print("|---|---|---:|---:|---:|---:|")
        for r in rows:
            ort = f"{r['ort_fps']:,.0f}" if r["ort_fps"] else "-"
            ratio = f"{r['ort_over_torch']:.2f}x" if r["ort_over_torch"] else "-"
            print(
                f"| {r['family']} | {r['graph']} | {r['frames']} | {ort} "
                f"| {r['torch_fps']:,.0f} | {ratio} |"
            )
        if "dance" in sources:
            print(
                f"\npaper (jacob2019, T4 GPU): {result['paper_fps_jacob2019_t4']:,} frames/s "
                "of generation"
            )
    return result


if __name__ == "__main__":
    main()

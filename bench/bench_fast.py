"""Speed of the fast style networks: frames per second, network only, for 240, 960 and
3,840 frames, onnxruntime vs torch eager, measured in one run.

    python -m bench.bench_fast [--style NAME] [--repeats 20] [--json]

Rows: one style's network (what holden2017's table times: 21,818 frames/s at 240 frames on
a 2017 GPU). The same weights in both runtimes: the shipped ONNX file and, for torch, the
checkpoint under ``checkpoints/fast/`` when present (else a fresh network of the same
size: the speed does not depend on the weights). Threads: the service's intra-op setting
(all cores) for both. Also times the engine's whole numpy + onnxruntime path (features,
network, rotations, foot clean-up) for the same lengths, without HTTP. Needs torch (a
training extra).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from motion import features as Fe

LENGTHS = (240, 960, 3840)
REPO = Path(__file__).resolve().parent.parent


def timed(fn, repeats: int) -> float:
    """Median seconds of ``fn()`` over ``repeats`` runs after two warm-ups."""
    fn()
    fn()
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> dict:
    import torch

    from service.config import Settings, available_cpus
    from service.engines.base import create_session
    from service.manifest import load_manifest
    from training import fast_common as FC

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--style", default=None, help="default: the first shipped style")
    p.add_argument("--repeats", type=int, default=20)
    p.add_argument("--json", action="store_true")
    p.add_argument("--no-engine", action="store_true", help="skip the end-to-end engine timing")
    args = p.parse_args(argv)

    settings = Settings()
    manifest = load_manifest(settings.models_dir[0])
    entry = next(m for m in manifest.models if m.family == "fast")
    styles = entry.extra["styles"]
    style = args.style or sorted(styles)[0]
    graph = styles[style]["graph"]
    threads = settings.intra_op_threads
    torch.set_num_threads(threads)

    session = create_session(settings.models_dir[0] / entry.graphs[graph].file, threads)
    ckpt_dir = FC.CHECKPOINTS
    net = FC.StyleNet().eval()
    if (ckpt_dir / f"style_{style}.pt").exists():
        from model_export.fast import load_style

        net, _ = load_style(ckpt_dir / f"style_{style}.pt")

    rows = []
    rng = np.random.default_rng(0)
    for frames in LENGTHS:
        x = rng.standard_normal((1, Fe.CONTROL_CHANNELS, frames)).astype(np.float32)
        xt = torch.from_numpy(x)

        def ort_style(x=x):
            return session.run(None, {"control": x})[0]

        def torch_style(xt=xt):
            with torch.inference_mode():
                return net(xt)

        for what, ort_fn, torch_fn in (("style network", ort_style, torch_style),):
            t_ort = timed(ort_fn, args.repeats)
            t_torch = timed(torch_fn, args.repeats)
            rows.append(
                {
                    "graph": what,
                    "frames": frames,
                    "ort_fps": frames / t_ort,
                    "torch_fps": frames / t_torch,
                    "ort_over_torch": t_torch / t_ort,
                    "ort_ms": t_ort * 1000,
                    "torch_ms": t_torch * 1000,
                }
            )

    engine_rows = []
    if not args.no_engine:
        engine_rows = time_engine(entry, settings, style, max(3, args.repeats // 5))

    result = {
        "style": style,
        "threads": threads,
        "cores": available_cpus(),
        "torch": torch.__version__,
        "rows": rows,
        "engine": engine_rows,
        "paper_fps_240_gpu_2017": 21818.18,
    }
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(
            f"style {style!r}, {threads} threads ({available_cpus()} cores), torch {torch.__version__}"
        )
        print("| graph | frames | onnxruntime frames/s | torch eager frames/s | ort / torch |")
        print("|---|---:|---:|---:|---:|")
        for r in rows:
            print(
                f"| {r['graph']} | {r['frames']} | {r['ort_fps']:,.0f} | {r['torch_fps']:,.0f} "
                f"| {r['ort_over_torch']:.2f}x |"
            )
        print(
            f"\nholden2017's networks (GTX 660 GPU): {result['paper_fps_240_gpu_2017']:,.0f} frames/s"
            " at 240 frames"
        )
        if engine_rows:
            print("\n| whole engine (no HTTP) | frames | ms | frames/s | stages ms |")
            print("|---|---:|---:|---:|---|")
            for r in engine_rows:
                stages = ", ".join(f"{k} {v:.0f}" for k, v in r["stages_ms"].items())
                print(f"| stylize | {r['frames']} | {r['ms']:.0f} | {r['fps']:,.0f} | {stages} |")
    return result


def time_engine(entry, settings, style: str, repeats: int) -> list[dict]:
    """The engine's ``stylize`` (features, network, rotations, foot clean-up) on a
    canonical walk tiled to each length."""
    from motion import bvh, retarget
    from motion import kinematics as K
    from service.engines.fast import FastEngine, FastJob
    from service.metrics import StageTimer

    engine = FastEngine(entry, settings.models_dir[0], settings)
    engine.load()
    motion = bvh.load(REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh")
    canon = retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion))
    out = []
    for frames in LENGTHS:
        idx = np.arange(frames) % canon.num_frames  # a loop: it jumps back, fine for timing
        clip = K.resample_at(canon, idx.astype(float), canon.fps)
        timers = []

        def run(clip=clip, timers=timers):
            timer = StageTimer(engine.name)
            engine.predict(FastJob(clip, style), timer)
            timers.append(timer.ms)

        seconds = timed(run, repeats)
        last = timers[-1]
        out.append(
            {"frames": frames, "ms": seconds * 1000, "fps": frames / seconds, "stages_ms": last}
        )
    return out


if __name__ == "__main__":
    main()

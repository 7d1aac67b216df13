"""Speed of the translator's whole request pipeline (aberman2020), without HTTP: frames per
second for a 240-frame clip, and the median milliseconds of every stage.

    python -m bench.bench_translator [--frames 240] [--repeats 10] [--json]

One run = what ``POST /v1/transfer`` does in the inference pool (``engine.infer``): parse the BVH -> map
and retarget to the canonical skeleton at 30 fps -> features -> content encoder and the
content's own style code -> decoder -> root trajectory -> foot clean-up (IK) -> time warp
(canonical result and the clip as sent) -> retarget back -> write BVH. Rows: a style by
name (table code) and a style by example clip (its parse, retarget and 3D encoder too).
The content is a Bandai walk (shared data) cut to ``--frames``, else the CMU fixture slowed
down to that many frames. Threads: the service's intra-op setting. Uses the shipped
``models/translator``; no torch.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from motion import bvh
from motion import features as Fe

REPO = Path(__file__).resolve().parent.parent
FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"


def content_clip(frames: int, data_dir: Path) -> tuple[str, bytes]:
    """``(description, BVH bytes)`` of a ``frames``-frame content clip."""
    walk = data_dir / "bandai" / "dataset-1" / "dataset-1_walk_proud_001.bvh"
    if walk.exists():
        motion = bvh.load(walk)
        if motion.num_frames >= frames:
            return f"Bandai {walk.stem}", bvh.dumps(motion.slice(0, frames)).encode()
    motion = bvh.load(FIXTURE)
    slowed = Fe.time_warp(motion, (motion.num_frames - 1) / (frames - 1), frames)
    return "CMU fixture slowed down", bvh.dumps(slowed).encode()


def main(argv: list[str] | None = None) -> dict:
    from service.clips import Upload
    from service.config import Settings
    from service.engines.translator import TranslatorEngine
    from service.manifest import load_manifest
    from service.metrics import StageTimer
    from service.requests import ContentClip, StyleSource, TransferRequest
    from training.data import data_dir

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=240)
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--style-name", default=None, help="default: the first style")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)

    settings = Settings()
    models = settings.models_dir[0]  # the first model folder: the shipped one by default
    entry = next(m for m in load_manifest(models).models if m.family == "translator")
    engine = TranslatorEngine(entry, models, settings)
    engine.load()
    name = args.style_name or engine.style_names[0]
    what, data = content_clip(args.frames, data_dir())
    style_file = data_dir() / "bandai" / "dataset-1" / "dataset-1_run_tired_001.bvh"
    inputs = {"style_name": StyleSource("style_name", name=name)}
    if style_file.exists():
        inputs["style_clip"] = StyleSource(
            "style", upload=Upload("style", data=style_file.read_bytes())
        )

    rows = {}
    for label, style in inputs.items():

        def once(style=style) -> tuple[float, dict, int]:
            started = time.perf_counter()
            timer = StageTimer(engine.name)
            content = ContentClip(Upload("content", data=data))
            out = engine.infer(TransferRequest(content, style), timer)
            return time.perf_counter() - started, dict(timer.ms), out.frames

        once()  # warm-up: the bucket's shapes
        runs = [once() for _ in range(args.repeats)]
        seconds = statistics.median(r[0] for r in runs)
        stages = {
            k: round(statistics.median(r[1].get(k, 0.0) for r in runs), 2) for k in runs[0][1]
        }
        rows[label] = {
            "seconds": round(seconds, 4),
            "frames_per_s": round(args.frames / seconds, 1),
            "output_frames": runs[0][2],
            "stages_ms": stages,
        }

    report = {
        "model": f"{engine.name}/{engine.version}",
        "content": what,
        "frames": args.frames,
        "repeats": args.repeats,
        "intra_op_threads": settings.intra_op_threads,
        "style_name": name,
        "rows": rows,
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(f"{report['model']}: {what}, {args.frames} frames, median of {args.repeats}")
        for label, row in rows.items():
            stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages_ms"].items())
            print(
                f"  {label:<11} {row['frames_per_s']:>8.1f} frames/s "
                f"({row['seconds'] * 1000:.1f} ms; out {row['output_frames']} frames)\n"
                f"    ms: {stages}"
            )
    return report


if __name__ == "__main__":
    main()

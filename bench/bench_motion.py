"""Motion-core speed: BVH parse and write frames/s, retargeting to canonical and back, and
BVH reading against bvhio 1.5.4 on the same real files.

    python -m bench.bench_motion [--data ../shared/data] [--repeat 3] [--compare-files 60]

Reports frames/s for every layout in the shared data, then MB/s of ``motion.bvh.load``
and ``bvhio.readAsBvh`` (keyframes loaded) over the same files (every CMU, Xia and
3ds Max file, Bandai files spread over both datasets up to ``--compare-files``), the two
read alternately file by file, best of ``--repeat`` passes each, in one run.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import kinematics as K

FILES = [
    "bandai/dataset-1/dataset-1_dance-short_normal_001.bvh",
    "cmu-31/05_20.bvh",
    "cmu-dance-43/60_09_scaled.bvh",
    "cmu-dance-3dsmax/94_01_indian_dance.bvh",
]


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def comparison_files(data: Path, count: int) -> list[Path]:
    """Every non-Bandai BVH of the shared data, then Bandai files evenly spread, ``count``
    in all (the Bandai files are many and alike)."""
    others = sorted(p for p in data.rglob("*.bvh") if "bandai" not in p.parts)
    bandai = sorted(data.glob("bandai/*/*.bvh"))
    step = max(1, len(bandai) // max(1, count - len(others)))
    return (others + bandai[::step])[:count]


def compare_bvhio(files: list[Path], repeat: int) -> dict:
    """MB/s of ours and of bvhio over ``files``, alternating file by file, best pass each."""
    import bvhio  # the dev extra's; a benchmark's comparison only

    size = sum(p.stat().st_size for p in files) / 1e6
    best = {"motion.bvh": float("inf"), "bvhio 1.5.4": float("inf")}
    for _ in range(repeat):
        spent = dict.fromkeys(best, 0.0)
        for path in files:
            for name, read in (("motion.bvh", bvh.load), ("bvhio 1.5.4", bvhio.readAsBvh)):
                t0 = time.perf_counter()
                read(str(path))
                spent[name] += time.perf_counter() - t0
        best = {k: min(best[k], spent[k]) for k in best}
    return {"files": len(files), "mb": round(size, 1)} | {
        k: round(size / v, 2) for k, v in best.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=os.environ.get("MOTION_DATA_DIR", "../shared/data"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--compare-files", type=int, default=60)
    args = parser.parse_args()
    print(
        f"{'file':45s} {'frames':>6s} {'joints':>6s} {'parse f/s':>10s} {'write f/s':>10s} "
        f"{'canon+back f/s':>14s} {'round-trip err':>14s}"
    )
    for rel in FILES:
        path = Path(args.data) / rel
        raw = path.read_bytes()
        m = bvh.loads(raw)
        t_parse = best_of(args.repeat, lambda raw=raw: bvh.loads(raw))
        t_write = best_of(args.repeat, lambda m=m: bvh.dumps(m))
        rig = retarget.make_rig(m.skeleton, m)

        def round_trip(m=m, rig=rig):
            return retarget.from_canonical(retarget.to_canonical(m, rig), rig, like=m)

        t_rt = best_of(args.repeat, round_trip)
        back = round_trip()
        idx = list(rig.mapping.values())
        err = np.linalg.norm(
            K.global_positions(back)[:, idx] - K.global_positions(m)[:, idx], axis=-1
        )
        height = rig.leg_length * 2.2  # body height ~ 2.2 leg lengths, also for flat rest poses
        n = m.num_frames
        print(
            f"{rel:45s} {n:6d} {m.skeleton.num_joints:6d} {n / t_parse:10.0f} {n / t_write:10.0f} "
            f"{n / t_rt:14.0f} {100 * err.mean() / height:13.3f}%"
        )
    files = comparison_files(Path(args.data), args.compare_files)
    result = compare_bvhio(files, args.repeat)
    ours, theirs = result["motion.bvh"], result["bvhio 1.5.4"]
    print(
        f"\nBVH reading, {result['files']} real files ({result['mb']} MB), one run: "
        f"motion.bvh {ours:.1f} MB/s, bvhio 1.5.4 {theirs:.1f} MB/s: {ours / theirs:.2f}x"
    )


if __name__ == "__main__":
    main()

"""Retargeting: round trips of every shared BVH, and speed against another commit, in one run.

    python -m bench.bench_retarget [--data ../shared/data] [--against REF] [--no-files]

Round trips, per file, on the mapped joints (% of body height; mean, 95th percentile, max):
``cli``, the command line's ``motion canonical IN --fps <its fps>`` written as BVH, then
``motion retarget canon.bvh --onto IN`` (joints between mapped ones hold their usual pose);
``own``, the service's path at the clip's own rate (``from_canonical(..., like=clip)``);
``30fps``, the service's path through 30 fps and back to the clip's rate and frame count.

Speed: the service's retargeting there and back (``make_rig``, ``to_canonical`` at 30 fps,
``from_canonical`` onto the clip) of the CMU fixture repeated to 240, 960 and 3,840 frames,
best of several runs, and with ``--against REF`` the same with ``motion/`` as it was at REF
(loaded side by side from git), interleaved so both see the same machine load.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import kinematics as K

REPO = Path(__file__).resolve().parent.parent
FIXTURE = REPO / "tests" / "data" / "cmu_02_01_walk_30fps.bvh"


def body_joints(rig) -> list[int]:
    """Mapped joints that are body joints (Bandai's floor root carries no pose)."""
    return [j for name, j in rig.mapping.items() if name != "joint_Root"]


def round_trip(path: Path) -> dict[str, np.ndarray]:
    m = bvh.load(path)
    rig = retarget.make_rig(m.skeleton, m)
    idx = body_joints(rig)
    ref = K.global_positions(m)[:, idx]

    def error(out) -> np.ndarray:
        return np.linalg.norm(K.global_positions(out)[:, idx] - ref, axis=-1) / rig.height * 100

    canon = retarget.to_canonical(m, rig, fps=None)
    text = bvh.loads(bvh.dumps(canon))  # as `motion canonical` writes it
    out = {
        "cli": error(retarget.retarget(text, m)),
        "own": error(retarget.from_canonical(canon, rig, like=m)),
        "30fps": error(retarget.from_canonical(retarget.to_canonical(m, rig), rig, like=m)),
    }
    out["rig"] = rig
    return out


def files_table(data: Path) -> None:
    paths = sorted(data.rglob("*.bvh"))
    print(f"round trips of {len(paths)} BVH files, % of body height on the mapped joints")
    head = f"{'file':60s} {'mapping':>17s}"
    for kind in ("cli", "own", "30fps"):
        head += f" {kind + ' mean/p95/max':>22s}"
    print(head)
    worst: dict[str, float] = {}
    for path in paths:
        res = round_trip(path)
        rig = res.pop("rig")
        line = f"{str(path.relative_to(data)):60s} {rig.method:>9s} {rig.confidence:7.2f}"
        for kind, err in res.items():
            line += f" {err.mean():6.3f} {np.percentile(err, 95):6.3f} {err.max():7.3f}"
            worst[kind] = max(worst.get(kind, 0.0), float(np.percentile(err, 95)))
        print(line, flush=True)
    print("worst 95th percentile: " + ", ".join(f"{k} {v:.3f}%" for k, v in worst.items()))


def load_motion_at(ref: str, folder: Path):
    """``motion`` as it was at git ``ref``, importable as ``motion_at_ref``."""
    target = folder / "motion_at_ref"
    target.mkdir()
    names = subprocess.run(
        ["git", "ls-tree", "--name-only", ref, "motion/"],
        cwd=REPO, check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    for name in names:
        if not name.endswith(".py"):
            continue
        text = subprocess.run(
            ["git", "show", f"{ref}:{name}"], cwd=REPO, check=True, capture_output=True, text=True
        ).stdout
        text = re.sub(r"^(\s*)(from|import) motion\b", r"\1\2 motion_at_ref", text, flags=re.M)
        (target / Path(name).name).write_text(text)
    sys.path.insert(0, str(folder))
    return (
        importlib.import_module("motion_at_ref.bvh"),
        importlib.import_module("motion_at_ref.retarget"),
    )


def speed_table(against: str | None, repeat: int) -> None:
    versions = {"now": (bvh, retarget)}
    tmp = None
    if against:
        tmp = tempfile.TemporaryDirectory()
        versions = {against[:10]: load_motion_at(against, Path(tmp.name)), **versions}

    def clip(mod_bvh, frames: int):
        m = mod_bvh.load(FIXTURE)
        reps = -(-frames // m.num_frames)
        lrot = np.concatenate([m.lrot] * reps)[:frames]
        return m.replace(lrot=lrot, lpos=np.concatenate([m.lpos] * reps)[:frames])

    def there_and_back(mod, m):
        rig = mod.make_rig(m.skeleton, m)
        return mod.from_canonical(mod.to_canonical(m, rig, fps=30.0), rig, like=m)

    print("\nretargeting there and back (make_rig, to_canonical at 30 fps, from_canonical),")
    print("CMU fixture (31 joints) repeated; best of runs, interleaved; ms")
    print(
        f"{'frames':>6s}"
        + "".join(f" {v:>12s}" for v in versions)
        + "   ratio  ms/1000 frames (now)"
    )
    for frames in (240, 960, 3840):
        clips = {v: clip(mods[0], frames) for v, mods in versions.items()}
        best = {v: float("inf") for v in versions}
        for v, (_, mod) in versions.items():
            there_and_back(mod, clips[v])  # warm up
        for _ in range(repeat if frames < 3840 else max(2, repeat // 2)):
            for v, (_, mod) in versions.items():
                t0 = time.perf_counter()
                there_and_back(mod, clips[v])
                best[v] = min(best[v], time.perf_counter() - t0)
        line = f"{frames:6d}" + "".join(f" {best[v] * 1e3:12.1f}" for v in versions)
        ratio = best[against[:10]] / best["now"] if against else float("nan")
        print(line + f" {ratio:7.2f}  {best['now'] * 1e6 / frames:8.2f}")
    if tmp is not None:
        tmp.cleanup()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=os.environ.get("MOTION_DATA_DIR", "../shared/data"))
    parser.add_argument("--against", help="git ref whose motion/ to time beside this one")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--no-files", action="store_true", help="speed only")
    args = parser.parse_args()
    if not args.no_files and Path(args.data).exists():
        files_table(Path(args.data))
    speed_table(args.against, args.repeat)


if __name__ == "__main__":
    main()

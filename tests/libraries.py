"""Libraries (``training.library``) made by code from the shared data, for trials of
``motion-style-train`` that a studio would run on its own capture.

    python -m tests.libraries --out cache/libraries/bandai2-mixamo

:func:`bandai2_on_mixamo`: Bandai dataset-2's subset (7 styles x 10 actions, 4 takes each)
re-sent onto a Mixamo-named rig (the CMU fixture's skeleton under Mixamo's names, Y up, in
centimetres, a person 175 cm tall; ``tests/rigs.py``), one BVH per take under an opaque
name, the labels only in ``labels.csv`` (held-out takes by the library's default rule).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from motion import bvh, retarget
from tests import rigs

HEIGHT_CM = 175.0


def mixamo_rig() -> retarget.Rig:
    """The CMU fixture's skeleton named as Mixamo names it, scaled to centimetres."""
    motion = rigs.renamed(rigs.load_fixture(), rigs.CMU_TO_MIXAMO)
    height = retarget.make_rig(motion.skeleton, motion).height
    motion = rigs.scaled(motion, HEIGHT_CM / height)
    return retarget.make_rig(motion.skeleton, motion)


def bandai2_on_mixamo(out: Path, data_dir: Path | None = None) -> Path:
    from training import data as D

    rig = mixamo_rig()
    out = Path(out)
    (out / "clips").mkdir(parents=True, exist_ok=True)
    rows = []
    for k, clip in enumerate(D.load_bandai(data_dir, datasets=(2,))):
        file = f"clips/take_{k:03d}.bvh"
        if not (out / file).exists():
            bvh.save(retarget.from_canonical(clip.motion, rig), out / file)
        rows.append([file, clip.style, clip.content, f"take_{k:03d}"])
    with open(out / "labels.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["file", "style", "content", "take"])
        writer.writerows(rows)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    out = bandai2_on_mixamo(args.out)
    print(f"{out}: {sum(1 for _ in open(out / 'labels.csv')) - 1} clips")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Bandai's two datasets as a library (``training.library``): the shipped models' data.

    python -m training.bandai_library [--out cache/libraries/bandai] [--datasets 1 2]

Writes ``--out`` (ignored by git, under ``cache/``): dataset-1's files as links to the data
folder, dataset-2's subset archive unpacked, and ``labels.csv``, whose labels are Bandai's
file names read once here (``dataset_content_style_take``, as its README says), with the
styles the two datasets name twice under one name (``motion.styles``), and the held-out
takes the shipped translator kept out (one dataset-2 take in ten, :func:`held_out_take`). Rows follow ``training.data.load_bandai``'s
order, so a training on this library draws what one on ``load_bandai`` drew.
"""

from __future__ import annotations

import argparse
import csv
import os
import tarfile
import zlib
from pathlib import Path

from motion.styles import canonical_style
from training import data as D
from training.library import LABELS

COLUMNS = ("file", "style", "content", "take", "actor", "mirror_ok", "held_out")


def held_out_take(name: str) -> bool:
    """Bandai's held-out takes (the library's ``held_out`` labels): one dataset-2 take in
    ten (and its mirror image), by a hash of its name: content of the validation examples,
    never trained on. Dataset 2 performs each action in each style four times, so its pairs
    stay complete without them."""
    base = name.removesuffix("~mirrored")
    return base.startswith("dataset-2") and zlib.crc32(base.encode()) % 10 == 0


def held_out_clip(clip) -> bool:
    """Whether ``clip`` (``training.data.Clip``) was kept out of training: its library's
    ``held_out`` label (``training.library``), else :func:`held_out_take` by its name
    (``training.data.load_bandai``'s clips carry no labels)."""
    if "held_out" in clip.extra:
        return bool(clip.extra["held_out"])
    return held_out_take(clip.name)


def _row(file: str) -> dict[str, str]:
    stem = Path(file).stem
    _, content, style, _ = stem.split("_")
    return {
        "file": file,
        "style": canonical_style(style),
        "content": content,
        "take": stem,
        "actor": "",
        "mirror_ok": "yes",
        "held_out": "yes" if held_out_take(stem) else "no",
    }


def write(out: Path, datasets: tuple[int, ...] = (1, 2), root: Path | None = None) -> Path:
    """The Bandai library in ``out``; returns it."""
    source = (root or D.data_dir()) / "bandai"
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if 1 in datasets:
        (out / "dataset-1").mkdir(exist_ok=True)
        for p in sorted((source / "dataset-1").glob("*.bvh")):
            link = out / "dataset-1" / p.name
            if not link.exists():
                os.symlink(p.resolve(), link)
            rows.append(_row(f"dataset-1/{p.name}"))
    if 2 in datasets:
        archive = source / "dataset-2" / "dataset-2-subset.tar.xz"
        with tarfile.open(archive) as tar:
            for member in tar:
                if not member.name.endswith(".bvh"):
                    continue
                target = out / "dataset-2" / Path(member.name).name
                if not target.exists():
                    target.parent.mkdir(exist_ok=True)
                    tmp = target.with_suffix(".tmp")
                    tmp.write_bytes(tar.extractfile(member).read())
                    os.replace(tmp, target)
                rows.append(_row(f"dataset-2/{target.name}"))
    with open(out / LABELS, "w", newline="") as f:
        writer = csv.DictWriter(f, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    return out


def default_folder() -> Path:
    return D.REPO / "cache" / "libraries" / "bandai"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=default_folder())
    parser.add_argument("--datasets", type=int, nargs="+", default=[1, 2], choices=[1, 2])
    args = parser.parse_args(argv)
    out = write(args.out, tuple(args.datasets))
    print(f"{out}: {sum(1 for _ in open(out / LABELS)) - 1} clips")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

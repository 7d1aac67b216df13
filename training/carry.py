"""What a lent GPU machine needs to train a model family, small enough to carry there.

    python -m training.carry [translator] [--out cache/carry] [--library LIB]
    python -m training.carry dance [--out cache/carry]

A lent machine receives the working tree and at most 64 MiB in all, and no data folder.
This writes into ``--out`` (ignored by git, as all of ``cache/``):

- ``translator``: the library's takes (``training.library``; Bandai's by default) with their
  rotations stored as float16 (``bandai.npz``, 12 MB against 25 MB for Bandai) and the pair
  alignments (``translator_alignments.npz``), so that there

      MOTION_CACHE_DIR=cache/carry python -m training.translator.fit \\
          --clips cache/carry/bandai.npz --device cuda ...

  trains without the data folder or librosa; name ``cache/carry`` in the run's ``carry``.
- ``dance``: the dance network's prepared sequences (``training.dance_data.prepare``: the
  songs' features and the dances on their clocks) as float16 (``dance_prepared.npz``, 18 MB),
  so that there

      python -m training.dance_schedule --device cuda \\
          --prepared cache/carry/dance_prepared.npz ...

  trains without the data folder; name ``cache/carry/dance_prepared.npz`` in the run's
  ``carry``.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from training import data as D
from training.library import read_library

ALIGNMENTS = "translator_alignments.npz"
DANCE = "dance_prepared.npz"


def carry_translator(out: Path, library: Path | None) -> None:
    alignments = D.cache_dir() / ALIGNMENTS
    if not alignments.exists():
        raise SystemExit(
            f"{alignments} is missing: run `make train-translator` here first "
            "(it computes every pair's alignment in its first minute)"
        )
    if library:
        clips = read_library(library)
    else:
        from training.translator.fit import bandai_library_clips

        clips = bandai_library_clips()
    D.save_clips(out / "bandai.npz", clips, "carried", half=True)
    shutil.copyfile(alignments, out / ALIGNMENTS)


def carry_dance(out: Path) -> None:
    from training.dance_data import prepare, save_prepared

    save_prepared(out / DANCE, prepare(), half=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("family", nargs="?", default="translator", choices=("translator", "dance"))
    parser.add_argument("--out", type=Path, default=D.REPO / "cache" / "carry")
    parser.add_argument("--library", type=Path, help="the translator's library (default: Bandai's)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.family == "dance":
        carry_dance(args.out)
    else:
        carry_translator(args.out, args.library)
    for p in sorted(args.out.iterdir()):
        print(f"{p}: {p.stat().st_size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

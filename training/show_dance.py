"""A picture of what the dance model makes: for each genre, a phrase of a dance generated for
a song, under the real dance of the same song at the same moment, as stick-figure film
strips in one SVG.

    python -m training.show_dance [--start 20] [--seconds 4] [--out docs/dance.svg]

Songs: the held-out song of each genre (``training.dance.VAL_TAKES``; the model never saw
them), and for tango, which has one song, that song (a training song). Columns: poses
every ``seconds / COLUMNS`` seconds from ``start`` seconds into the real dance, each seen from
the dancer's left and from its front, relative to its own hips on the floor (so the
figure's shape, not its path, is compared). Left limbs blue, right limbs red. The generated
dance comes from the shipped engine as ``POST /v1/dance`` makes it (seed 0, the genre
given), on the part of the song the real dance covers.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from motion.skeleton import Motion
from training.show_styles import document

REPO = Path(__file__).resolve().parent.parent
COLUMNS = 8


def render(rows: list[tuple[str, Motion]], start: float, seconds: float, title: str) -> str:
    """An SVG document of film strips, one per ``(label, canonical motion)``, each showing
    :data:`COLUMNS` poses from ``start`` over ``seconds``."""
    times = start + np.arange(COLUMNS) * seconds / COLUMNS
    return document(
        [(label, motion, np.clip(np.round(times * motion.fps).astype(int), 0, motion.num_frames - 1))
         for label, motion in rows],
        title,
    )  # fmt: skip


def phrases(seed: int = 0) -> list[tuple[str, Motion]]:
    """``(label, motion)`` rows: per genre the real dance of its song, then the generated."""
    from motion import audio_decode
    from service.engines.dance import DanceJob
    from service.metrics import StageTimer
    from training import dance as TD
    from training import dance_alignment as DA
    from training.dance_data import retime
    from training.data import data_dir, load_dance_with_melody
    from training.eval_dance import load_engine

    engine, _ = load_engine()
    table = DA.load_table()
    clips = {c.name: c for c in load_dance_with_melody()}
    chosen = {}
    for name in sorted(TD.VAL_TAKES) + sorted(clips):
        genre = clips[name].genre
        if genre not in chosen and DA.alignment_for(name, table) is not None:
            chosen[genre] = name
    rows = []
    for genre in sorted(chosen):
        name = chosen[genre]
        clip, alignment = clips[name], DA.alignment_for(name, table)
        real = retime(clip.motion, alignment.rate)
        samples, sr = audio_decode.decode(
            data_dir() / Path(clip.extra["audio"]).parent / "audio.mp3"
        )
        first = int(round(max(alignment.offset, 0.0) * sr))
        part = samples[first : first + int(round(real.num_frames / real.fps * sr))]
        job = DanceJob(part, sr, genre=genre, seed=seed)
        out = engine.predict(job, StageTimer(engine.name)).motion
        held = "held-out song" if name in TD.VAL_TAKES else "training song"
        rows += [(f"{genre}: real ({name[6:]})", real), (f"generated ({held})", out)]
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--start", type=float, default=20.0, help="seconds into each dance")
    p.add_argument("--seconds", type=float, default=4.0, help="length of the phrase")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "dance.svg")
    args = p.parse_args(argv)
    rows = phrases()
    title = (
        f"Dance phrases, {args.seconds:g} s from {args.start:g} s: the real dance of each "
        "genre's song, and the one generated for it (each pose from the left and from the front)"
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(render(rows, args.start, args.seconds, title))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

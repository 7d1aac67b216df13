"""The beat a listener taps, checked on every shared song: the tempo the service's tracker
finds with its general prior and with the requested genre's prior, against the song's
danced tempo.

    python -m training.dance_tempo [--json runs/eval/dance_tempo.json]

Reference (``reference_tempo``): the danced tempo where the dance's step cycle locks to the
music (``training/dance_alignment.json``, verified or rate-corrected: a waltz rises and falls
once a bar of three beats, the Latin figures and the tango every two beats, so the locked
cycle fixes the beat's octave); elsewhere (the five cha-chas, three rumbas: no stable
locking) librosa's tempo as the alignment study tracked it.

The genre's level (``motion.beat_tracking.tempo_curve``'s ``level_bpm``): among the tracked
tempo's metrical levels, the one a log-normal of ``GENRE_TEMPO_OCTAVES`` around the genre's
tempo (``motion.beat_tracking.GENRE_TEMPO``) and the periodicity favour. Its centres are fitted here
as the geometric mean of the references of a genre's songs: leaving each song out in turn
for the check, and on the training songs only (``training.dance.VAL_TAKES`` left out) for
the centres the service ships (``--fit``). A tempo is right within 4 % of the reference
(MIREX's tolerance).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from motion import audio_decode, spectral
from motion import beat_tracking as BT
from training.reports import publish

TOLERANCE = 0.04
CYCLE_BEATS = {"cha-cha": 2, "rumba": 2, "tango": 2, "waltz": 3}  # dance_alignment's
BALLROOM_TEMPO = {"cha-cha": 124.0, "rumba": 104.0, "tango": 128.0, "waltz": 87.0}
"""Beats a minute of the competition tempi (WDSF bars a minute: cha-cha 30-32, rumba 25-27,
tango 31-33, slow waltz 28-30, the middle times the beats a bar): a genre's centre when no
song of it is left to fit one."""


def reference_tempo(row: dict) -> tuple[float, str]:
    """``(bpm, how)`` of one dance of the alignment table: danced or tracked (librosa)."""
    bpm = row["tempo_bpm"] * CYCLE_BEATS[row["genre"]] / row["cycle_beats"]
    return float(bpm), "danced" if row["verdict"] in ("verified", "rate-corrected") else "tracked"


def genre_centres(references: dict[str, tuple[str, float]], leave_out=()) -> dict[str, float]:
    """Geometric mean of the reference tempi of each genre's songs, ``leave_out`` not
    counted (a genre with no song left keeps the ballroom centre)."""
    by_genre: dict[str, list[float]] = {}
    for name, (genre, bpm) in references.items():
        if name not in leave_out:
            by_genre.setdefault(genre, []).append(bpm)
    centres = dict(BALLROOM_TEMPO)
    centres.update({g: float(np.exp(np.mean(np.log(v)))) for g, v in by_genre.items()})
    return centres


def right(bpm: float, reference: float) -> bool:
    return abs(bpm / reference - 1.0) <= TOLERANCE


def study(log=print) -> dict:
    from training import dance_alignment as DA
    from training.data import data_dir

    table = DA.load_table()["dances"]
    references = {n: (r["genre"], reference_tempo(r)[0]) for n, r in table.items()}
    root = data_dir() / "dance-with-melody"
    rows = {}
    for name, row in sorted(table.items()):
        genre = row["genre"]
        reference, how = reference_tempo(row)
        samples, sr = audio_decode.decode(root / name / "audio.mp3")
        envelope = spectral.beat_onset_strength(samples, sr)
        general = BT.tempo_curve(envelope).bpm
        centre = genre_centres(references, leave_out=(name,))[genre]
        prior = BT.tempo_curve(envelope, level_bpm=centre).bpm
        rows[name] = {
            "genre": genre,
            "reference_bpm": round(reference, 1),
            "reference": how,
            "general_prior_bpm": round(general, 1),
            "genre_prior_bpm": round(prior, 1),
            "genre_centre_left_out": round(centre, 1),
            "general_right": right(general, reference),
            "genre_right": right(prior, reference),
        }
        log(f"{name}: {json.dumps(rows[name])}")
    return {
        "songs": rows,
        "right_general": sum(r["general_right"] for r in rows.values()),
        "right_genre": sum(r["genre_right"] for r in rows.values()),
        "tolerance": TOLERANCE,
        "octaves": BT.GENRE_TEMPO_OCTAVES,
    }


def markdown(report: dict) -> str:
    lines = [
        f"Tempo of every shared song ({len(report['songs'])}): right (within "
        f"{report['tolerance']:.0%} of the danced, else librosa's, tempo) with the general "
        f"prior {report['right_general']}, with the genre's prior ({report['octaves']:g} "
        f"octaves, its centre fitted with the song left out) {report['right_genre']}.",
        "",
        "| song | genre | reference bpm | general prior | genre prior (centre) |",
        "|---|---|---|---|---|",
    ]
    for name, r in report["songs"].items():
        mark = {True: "", False: " x"}
        lines.append(
            f"| {name} | {r['genre']} | {r['reference_bpm']} ({r['reference']}) | "
            f"{r['general_prior_bpm']}{mark[r['general_right']]} | "
            f"{r['genre_prior_bpm']}{mark[r['genre_right']]} ({r['genre_centre_left_out']}) |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", type=Path, default=None)
    p.add_argument(
        "--fit",
        action="store_true",
        help="print the genre centres fitted on the training songs (what motion.beat_tracking ships)",
    )
    args = p.parse_args(argv)
    if args.fit:
        from training import dance as TD
        from training import dance_alignment as DA

        table = DA.load_table()["dances"]
        refs = {n: (r["genre"], reference_tempo(r)[0]) for n, r in table.items()}
        centres = genre_centres(refs, leave_out=TD.VAL_TAKES)
        print(json.dumps({g: round(c, 1) for g, c in centres.items()}))
        return 0
    report = study()
    publish(report, markdown(report), args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

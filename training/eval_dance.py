"""Evaluation of the shipped dance model (jacob2019 made to work) on held-out songs.

    python -m training.eval_dance [--seeds 3] [--json PATH] [--manifest]

Everything runs through the shipped engine exactly as ``POST /v1/dance`` does (onnxruntime
step loop, smoothing, beat warp, foot clean-up), on the part of each held-out song that its
real dance covers (``training.dance.VAL_TAKES``, placed by the alignment study). Figures:

- **beat alignment** (the AIST++ score: each kinematic beat, a local minimum of joint
  speed, scored ``exp(-d^2 / 2 sigma^2)`` by its distance to the nearest music beat) of the
  generated dances, with and without the beat warp, beside the real dance's score on the
  same beats and the chance level (the same kinematic beats against music beat grids
  shifted by a random fraction of a beat);
- **foot sliding** (``motion.contacts.canonical_foot_sliding``, cm/s) against the real dance;
- **energy over 10 minutes**: mean joint speed per 30 seconds of one generation per seed
  over the held-out songs' music looped to 10 minutes, beside the real dances' mean (no freezing,
  no blow-up);
- **genre**: a classifier of dance motion (``training.eval_style.ClipClassifier``) trained on
  the real dances of the training songs, asked to name the genre of each generated dance.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from motion import beat_warp as BW
from motion import contacts as CT
from motion import dance_features as DF
from motion import kinematics as K
from motion.skeleton import Motion

TEN_MINUTES = 600.0
BLOCK = 30.0  # seconds per energy block


def load_engine():
    from service.config import Settings
    from service.engines.dance import DanceEngine
    from service.manifest import load_manifest

    settings = Settings(max_audio_seconds=TEN_MINUTES + 60)
    entry = next(m for m in load_manifest(settings.models_dir).models if m.family == "dance")
    engine = DanceEngine(entry, settings.models_dir, settings)
    engine.load()
    return engine, entry


def body_speed(motion: Motion) -> np.ndarray:
    """Per-frame mean joint speed (cm/s) relative to the hips' floor point."""
    gpos = K.global_positions(motion)
    return BW.joint_speed(gpos, motion.fps)


def energy_blocks(speed: np.ndarray, fps: float) -> dict:
    """Mean joint speed (cm/s) of each whole ``BLOCK`` of a per-frame ``speed``: its lowest,
    highest, first and last."""
    per = int(BLOCK * fps)
    blocks = speed[: len(speed) // per * per].reshape(-1, per).mean(axis=1)
    figures = {"per_30s_min": blocks.min(), "per_30s_max": blocks.max(),
               "first_30s": blocks[0], "last_30s": blocks[-1]}  # fmt: skip
    return {k: round(float(v), 1) for k, v in figures.items()}


def bas(motion: Motion, beats: np.ndarray) -> tuple[float, float]:
    """Beat alignment score and its shifted-grid chance level."""
    kin = BW.kinematic_beats(K.global_positions(motion), motion.fps)
    return BW.beat_alignment_score(kin, beats), BW.shifted_grid_baseline(kin, beats, seed=0).mean


def held_out_songs():
    """``(name, genre, real motion on the song's clock, song samples it covers, sr, beats in
    seconds from its first frame)`` for each held-out song; training songs' real dances."""
    from motion import audio
    from training import dance as TD
    from training import dance_alignment as DA
    from training.data import data_dir, load_dance_with_melody

    table = DA.load_table()
    held, train = [], []
    for clip in load_dance_with_melody():
        alignment = DA.alignment_for(clip.name, table)
        if alignment is None:
            continue
        motion = TD.retime(clip.motion, alignment.rate)
        if clip.name not in TD.VAL_TAKES:
            train.append((clip.genre, motion))
            continue
        folder = data_dir() / Path(clip.extra["audio"]).parent
        samples, sr = audio.decode(folder / "audio.mp3")
        start = int(round(alignment.offset * sr))
        stop = start + int(round(motion.num_frames / motion.fps * sr))
        beats = np.asarray(DA.analyse_music(folder)["beats"], np.float64) - alignment.offset
        beats = beats[(beats >= 0) & (beats <= motion.num_frames / motion.fps)]
        held.append((clip.name, clip.genre, motion, samples[start:stop], sr, beats))
    return held, train


def evaluate(seeds: int = 3, log=print) -> dict:
    from service.metrics import StageTimer
    from training.eval_style import ClipClassifier, window_features

    engine, entry = load_engine()
    held, train = held_out_songs()
    genre_clf = ClipClassifier([window_features(m) for _, m in train], [g for g, _ in train])
    report: dict = {
        "model": f"{entry.name} {entry.version}",
        "model_name": entry.name,
        "model_version": entry.version,
        "seeds": seeds,
        "songs": {},
    }
    rows = {k: [] for k in ("real", "generated", "generated_no_warp")}
    chance = {k: [] for k in rows}
    sliding = {"real": [], "generated": []}
    genre_hits, real_genre_hits = [], []
    for name, genre, real, samples, sr, beats in held:
        score, base = bas(real, beats)
        rows["real"].append(score)
        chance["real"].append(base)
        sliding["real"].append(CT.canonical_foot_sliding(real))
        real_genre_hits.append(genre_clf.predict(window_features(real)) == genre)
        song = {"genre": genre, "seconds": round(len(samples) / sr, 1), "beats": len(beats),
                "real": {"bas": round(score, 4), "chance": round(base, 4)}}  # fmt: skip
        for seed in range(seeds):
            for label, warp in (("generated", True), ("generated_no_warp", False)):
                out = engine.dance(samples, sr, StageTimer(engine.name), genre=genre,
                                   seed=seed, beat_warp=warp).motion  # fmt: skip
                s, b = bas(out, beats)
                rows[label].append(s)
                chance[label].append(b)
                song.setdefault(label, []).append({"bas": round(s, 4), "chance": round(b, 4)})
                if warp:
                    sliding["generated"].append(CT.canonical_foot_sliding(out))
                    genre_hits.append(genre_clf.predict(window_features(out)) == genre)
        report["songs"][name] = song
        log(f"{name}: {json.dumps(song)}")

    report["beat_alignment"] = {
        k: {"bas": round(float(np.mean(v)), 4), "chance": round(float(np.mean(chance[k])), 4),
            "n": len(v)}
        for k, v in rows.items()
    }  # fmt: skip
    report["foot_sliding_cm_s"] = {k: round(float(np.mean(v)), 2) for k, v in sliding.items()}
    report["genre_accuracy"] = {
        "generated": round(float(np.mean(genre_hits)), 4),
        "real_held_out": round(float(np.mean(real_genre_hits)), 4),
        "chance": round(1 / len(DF.MUSIC_GENRES), 4),
        "n_generated": len(genre_hits),
    }

    # ten minutes of the held-out songs' music, one generation per seed: a feedback loop that
    # freezes or blows up for one seed only would pass a single-seed check
    sr = held[0][4]
    loop = np.concatenate([h[3] for h in held if h[4] == sr])
    long_song = np.resize(loop, int(TEN_MINUTES * sr))
    real_speed = float(np.mean([body_speed(h[2]).mean() for h in held]))
    per_seed = []
    for seed in range(seeds):
        out = engine.dance(long_song, sr, StageTimer(engine.name), genre="waltz", seed=seed)
        per_seed.append({"seed": seed, "frames": out.motion.num_frames,
                         **energy_blocks(body_speed(out.motion), out.motion.fps)})  # fmt: skip
        log(f"ten minutes, seed {seed}: {json.dumps(per_seed[-1])}")
    report["ten_minutes"] = {
        "frames": per_seed[0]["frames"],
        "seeds": seeds,
        "real_mean": round(real_speed, 1),
        "per_30s_min": min(r["per_30s_min"] for r in per_seed),
        "per_30s_max": max(r["per_30s_max"] for r in per_seed),
        "per_seed": per_seed,
        "units": "mean joint speed, cm/s",
    }
    return report


def markdown(report: dict) -> str:
    ba = report["beat_alignment"]
    lines = [
        f"**dance** ({report['model']}): {len(report['songs'])} held-out songs x "
        f"{report['seeds']} seeds",
        "",
        "| dance | beat alignment | chance (shifted beats) | foot sliding (cm/s) |",
        "|---|---|---|---|",
        f"| real | {ba['real']['bas']:.3f} | {ba['real']['chance']:.3f} | "
        f"{report['foot_sliding_cm_s']['real']:.1f} |",
        f"| generated (as served) | {ba['generated']['bas']:.3f} | "
        f"{ba['generated']['chance']:.3f} | {report['foot_sliding_cm_s']['generated']:.1f} |",
        f"| generated, no beat warp | {ba['generated_no_warp']['bas']:.3f} | "
        f"{ba['generated_no_warp']['chance']:.3f} | - |",
    ]
    g, t = report["genre_accuracy"], report["ten_minutes"]
    lines += [
        "",
        f"Genre classifier (trained on real training-song dances): generated "
        f"{g['generated']:.0%} (n={g['n_generated']}), real held-out {g['real_held_out']:.0%}, "
        f"chance {g['chance']:.0%}.",
        f"Ten minutes ({t['frames']} frames, {t['seeds']} seeds): mean joint speed per 30 s "
        f"from {t['per_30s_min']} to {t['per_30s_max']} cm/s; real dances {t['real_mean']} "
        "cm/s. First and last 30 s by seed: "
        + ", ".join(f"{r['first_30s']} / {r['last_30s']}" for r in t["per_seed"])
        + ".",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument(
        "--manifest",
        action="store_true",
        help="also record the figures in the model's manifest entry "
        "(metrics.evaluation.held_out_songs), so they travel with the model",
    )
    args = p.parse_args(argv)
    report = evaluate(args.seeds)
    print()
    print(markdown(report))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1))
    if args.manifest:
        from service.config import Settings

        record_in_manifest(report, Settings().models_dir)
    return 0


def record_in_manifest(report: dict, models_dir: Path) -> None:
    """The report's summary figures into its model's manifest entry (refused for another
    version of the model; a new export drops them)."""
    from model_export.manifest import measuring_machine, put_evaluation

    figures = {
        "songs": len(report["songs"]),
        "seeds": report["seeds"],
        "beat_alignment": report["beat_alignment"],
        "foot_sliding_cm_s": report["foot_sliding_cm_s"],
        "genre_accuracy": report["genre_accuracy"],
        "ten_minutes": report["ten_minutes"],
        "measured": time.strftime("%Y-%m-%d"),
        "machine": measuring_machine(),
        "by": "python -m training.eval_dance (beat alignment: AIST++ score; foot sliding in "
        "cm/s; genre: logistic regression on real training-song dances)",
    }
    put_evaluation(
        report["model_name"], report["model_version"], "held_out_songs", figures, models_dir
    )


if __name__ == "__main__":
    raise SystemExit(main())

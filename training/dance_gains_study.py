"""Study (rules 25, 26 and 28, docs/dance_alignment.md): the phrase band of each joint scaled
by a gain per genre, measured on the fold's training songs; not shipped (11a: the legs' jerk;
11b, the legs capped at 1: the distance).

    python -m training.dance_gains_study gains OUT.json
    python -m training.dance_gains_study judge GAINS.json JUDGED.json [--first-seed N]
        [--legs-capped]

``gains``: for the shipped fold models (``models/``, ``runs/eval/models-fold1`` from ``make
eval-dance``), per music genre with training songs, sqrt(real / generated) phrase-band power
per joint (six rotation channels) and of the root height, within [2/3, 3/2]: real = the
fold's training songs' prepared features, low-passed as the engine does; generated = the fold
model's own-genre rollouts on those songs (seeds 100-102). ``judge``: ``make judge-dance``'s
set on the same models with the gains applied after the engine's low-pass.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

from motion import dance_features as DF

REPO = Path(__file__).resolve().parent.parent
FOLDERS = (REPO / "models", REPO / "runs" / "eval" / "models-fold1")
LOW = butter(2, 0.5 / (0.5 * DF.FPS), output="sos")
HIGH = butter(2, 3.0 / (0.5 * DF.FPS), output="sos")
GROUPS = len(DF.BODY) + 1


def band(x: np.ndarray) -> np.ndarray:
    return sosfiltfilt(HIGH, x, axis=0) - sosfiltfilt(LOW, x, axis=0)


def powers(raw: np.ndarray) -> tuple[np.ndarray, int]:
    b = band(np.asarray(raw, np.float64)[:, : DF.HEIGHT + 1])
    rot = (b[:, : DF.ROTATION_CHANNELS] ** 2).reshape(len(b), len(DF.BODY), 6).mean(axis=(0, 2))
    return np.append(rot, (b[:, DF.HEIGHT] ** 2).mean()), len(b)


def gains(models: Path) -> tuple[str, dict]:
    from training.dance_data import prepare
    from training.eval_dance import load_engine

    engine, entry = load_engine(models)
    held = set(entry.extra["validation_takes"])
    seqs = [s for s in prepare(log=lambda *a: None) if s.has_music and s.name not in held]
    out = {}
    for genre in DF.MUSIC_GENRES:
        mine = [s for s in seqs if s.genre == DF.genre_index(genre)]
        if not mine:
            continue
        real, gen = np.zeros(GROUPS), np.zeros(GROUPS)
        for s in mine:
            p, n = powers(DF.smooth_features(s.motion))
            real += p * n
            code, _ = engine.encode(engine.stats.normalize_audio(s.audio))
            for seed in (100, 101, 102):
                rng = np.random.default_rng(seed)
                start = engine.start_poses[rng.integers(len(engine.start_poses))]
                poses = engine.rollout(code, DF.genre_vector(genre),
                                       engine.stats.normalize_motion(start), int(rng.integers(2**31)))  # fmt: skip
                q, m = powers(DF.smooth_features(engine.stats.denormalize_motion(poses)))
                gen += q * m / 3
        ratio = np.sqrt(real / np.maximum(gen, 1e-12))
        out[genre] = {"songs": [s.name for s in mine],
                      "gains": np.round(np.clip(ratio, 2 / 3, 3 / 2), 4).tolist()}  # fmt: skip
    return entry.name, out


def judge(table: dict, out: Path, first_seed: int, legs_capped: bool) -> None:
    from service.engines import dance as SD
    from training import eval_dance as ED

    current: dict = {}
    dance = SD.DanceEngine._dance

    def _dance(self, job, music, networks, timer):
        current["g"] = table[self.entry.name].get(networks.genre)
        try:
            return dance(self, job, music, networks, timer)
        finally:
            current.pop("g")

    smooth = DF.smooth_features

    def gained(x, *a, **k):
        y = smooth(x, *a, **k)
        if current["g"] is None or len(y) <= 60:
            return y
        g = np.asarray(current["g"]["gains"])
        if legs_capped:  # 11b (rule 28): the leg joints' own jerk kept
            from training.judges import LEGS

            legs = np.isin(DF.BODY, LEGS)
            g = np.where(np.append(legs, False), np.minimum(g, 1.0), g)
        gain = np.append(np.repeat(g[:-1], 6), g[-1])
        y = y.astype(np.float64)
        y[:, : DF.HEIGHT + 1] += (gain - 1.0) * band(y[:, : DF.HEIGHT + 1])
        return y.astype(np.float32)

    SD.DanceEngine._dance = _dance
    DF.smooth_features = gained
    ED.main(["--held-out-only", "--whole-songs", "--seeds", "12", "--fold-models",
             str(FOLDERS[1]), "--first-seed", str(first_seed), "--json", str(out)])  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=("gains", "judge"))
    p.add_argument("paths", nargs="+", type=Path)
    p.add_argument("--first-seed", type=int, default=0)
    p.add_argument("--legs-capped", action="store_true")
    args = p.parse_args()
    if args.what == "gains":
        table = dict(gains(folder) for folder in FOLDERS)
        args.paths[0].write_text(json.dumps(table, indent=1))
    else:
        judge(json.loads(args.paths[0].read_text()), args.paths[1], args.first_seed, args.legs_capped)


if __name__ == "__main__":
    main()

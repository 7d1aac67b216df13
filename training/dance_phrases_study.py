"""Study 13a (issue 67, rule 30 in docs/dance_alignment.md): a dance of real phrases
(``motion.dance_phrases``) in place of the step network's rollout, on each fold's shipped
models. The fold's library is its training songs' dances (a held-out song's dance is never
in it), standardised with the fold model's statistics, with the fold's audio code of the
music they were danced to. Everything else is the shipped engine's.

    python -m training.dance_phrases_study OUT.json --first-seed 48     # 13a, rule 30
    python -m training.dance_phrases_study OUT.json --first-seed 60 --no-foot-cleanup  # 13b
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from dataclasses import replace

import numpy as np

from motion import dance_phrases as DP
from training.dance import FOLDS
from training.dance_data import prepare


def fold_library(engine, fold: int) -> DP.PhraseLibrary:
    """The fold's training songs (and the CMU dances of the genres without music)."""
    seqs = [s for s in prepare(log=lambda *a: None) if s.name not in FOLDS[fold]]
    motion, music, genre, song = [], [], [], []
    for i, s in enumerate(seqs):
        code, _ = engine.encode(engine.stats.normalize_audio(s.audio))
        motion.append(engine.stats.normalize_motion(s.motion).astype(np.float32))
        music.append(code.astype(np.float32))
        genre.append(np.full(len(s.motion), s.genre))
        song.append(np.full(len(s.motion), i))
    return DP.PhraseLibrary(*(np.concatenate(x) for x in (motion, music, genre, song)))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("json")
    p.add_argument("--first-seed", type=int, required=True)
    p.add_argument(
        "--no-foot-cleanup",
        action="store_true",
        help="the phrases' own feet, not the engine's clean-up (rule 31)",
    )
    a = p.parse_args(argv)

    import service.engines.dance as E
    from training import eval_dance as ED

    samplers: dict[int, DP.PhraseSampler] = {}
    runs: Counter = Counter()

    def rollout(self, code, genre, start, seed):
        fold = 1 if "fold1" in self.entry.name else 0
        if fold not in samplers:
            samplers[fold] = DP.PhraseSampler(fold_library(self, fold))
        poses, joins = samplers[fold].dance(
            code, int(np.argmax(genre)), np.random.default_rng(seed)
        )
        runs["phrases"] += len(joins)
        runs["continued"] += sum(
            b == a + DP.PHRASE for (_, a), (_, b) in zip(joins, joins[1:], strict=False)
        )
        return poses

    E.DanceEngine.rollout = rollout
    if a.no_foot_cleanup:
        dance = E.DanceEngine._dance

        def without_cleanup(self, job, music, out, timer):
            return dance(self, replace(job, foot_cleanup=False), music, out, timer)

        E.DanceEngine._dance = without_cleanup
    ED.main(["--held-out-only", "--whole-songs", "--fold-models", "runs/eval/models-fold1",
             "--first-seed", str(a.first_seed), "--json", a.json])  # fmt: skip
    print(json.dumps({"phrases": runs["phrases"], "joins_that_continue_the_same_dance":
                      runs["continued"]}))  # fmt: skip


if __name__ == "__main__":
    main()

"""Study 13a (issue 67, rule 30 in docs/dance_alignment.md): a dance of real phrases
(``motion.dance_phrases``) in place of the step network's rollout, on each fold's shipped
models. The fold's library is its training songs' dances (a held-out song's dance is never
in it), standardised with the fold model's statistics, with the fold's audio code of the
music they were danced to. Everything else is the shipped engine's.

    python -m training.dance_phrases_study OUT.json --first-seed 48     # 13a, rule 30
    python -m training.dance_phrases_study OUT.json --first-seed 60 --no-foot-cleanup  # 13b
    python -m training.dance_phrases_study OUT.json --first-seed 72 --motion-space  # 13c
    python -m training.dance_phrases_study OUT.json --first-seed 84 --clean-joins  # 13d
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from dataclasses import replace

import numpy as np

import service.engines.dance as E
from motion import beat_warp as BW
from motion import dance_features as DF
from motion import dance_phrases as DP
from motion import kinematics as K
from motion.anatomy import hinged
from training.dance import FOLDS
from training.dance_data import prepare


def real_dances() -> dict:
    """Each aligned song's real dance on the song's clock, the frames of its sequence."""
    from training import dance_alignment as DA
    from training.dance_data import retime
    from training.data import load_dance_with_melody

    table, out = DA.load_table(), {}
    for clip in load_dance_with_melody():
        alignment = DA.alignment_for(clip.name, table)
        if alignment is not None:
            out[clip.name] = retime(clip.motion, alignment.rate)
    return out


def fold_library(
    engine, fold: int, motion_space: bool = False, clean: bool = False
) -> DP.PhraseLibrary:
    """The fold's training songs (and the CMU dances of the genres without music; with
    ``motion_space``, the songs only, each with its dance itself; with ``clean`` too, each
    take's frames inside a stalling 5-s window left out, and its foot contacts)."""
    from training.eval_dance import body_speed

    seqs = [s for s in prepare(log=lambda *a: None) if s.name not in FOLDS[fold]]
    dances = real_dances() if motion_space else {}
    if motion_space:
        seqs = [s for s in seqs if s.name in dances]
    motion, music, genre, song, lrot, hips, usable, contacts = [], [], [], [], [], [], [], []
    for i, s in enumerate(seqs):
        code, _ = engine.encode(engine.stats.normalize_audio(s.audio))
        motion.append(engine.stats.normalize_motion(s.motion).astype(np.float32))
        music.append(code.astype(np.float32))
        genre.append(np.full(len(s.motion), s.genre))
        song.append(np.full(len(s.motion), i))
        if motion_space:
            real = dances[s.name]
            assert real.num_frames == len(s.motion), s.name
            lrot.append(real.lrot.astype(np.float32))
            if clean:
                real = DF.level_floor(real)
            hips.append(real.lpos[:, DP.HIPS].astype(np.float32))
            if clean:
                still = np.ones(real.num_frames, bool)
                length = int(round(DF.STALL_SECONDS * real.fps))
                for start in np.round(DF.stalls(body_speed(real), real.fps) * real.fps):
                    still[int(start) : int(start) + length] = False
                usable.append(still)
                contacts.append(DF.dance_contacts(K.global_positions(real), real.fps))
    arrays = [np.concatenate(x) for x in (motion, music, genre, song)]
    if motion_space:
        arrays += [np.concatenate(lrot), np.concatenate(hips)]
    if clean:
        arrays += [np.concatenate(usable), np.concatenate(contacts)]
    return DP.PhraseLibrary(*arrays)


def dance_of_phrases(engine, job, music, genre: str, probs: dict, motion):
    """The engine's steps after the rollout that a dance of real motion keeps: the hinge
    limits and the beat warp (no low-pass, standstills or foot clean-up)."""
    warnings = []
    if job.genre is None:
        warnings.append(f"genre not given: predicted {genre} (p = {probs[genre]:.2f})")
    tempo, beats, pulses = music.features.for_genre(genre)
    motion = hinged(motion)
    if job.beat_warp and len(beats) >= 2:
        motion = BW.warp_to_beats(motion, pulses).motion
    bas, chance = BW.alignment(motion, beats)
    return E.DanceResult(motion, genre, probs, job.genre is not None, tempo, beats, bas,
                         chance, warnings)  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("json")
    p.add_argument("--first-seed", type=int, required=True)
    p.add_argument(
        "--no-foot-cleanup",
        action="store_true",
        help="the phrases' own feet, not the engine's clean-up (rule 31)",
    )
    p.add_argument(
        "--motion-space",
        action="store_true",
        help="phrases joined on the dancers' own motion, not decoded features (rule 32)",
    )
    p.add_argument(
        "--clean-joins",
        action="store_true",
        help="13c with still stretches left out, the joins' feet pinned and tango danced by"
        " the network (rule 33)",
    )
    a = p.parse_args(argv)

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

    network_predict = E.DanceEngine.predict

    def predict(self, job, timer):
        fold = 1 if "fold1" in self.entry.name else 0
        if a.clean_joins and job.genre == "tango":  # one noisy take: the network dances it
            runs["tango by the network"] += 1
            return network_predict(self, job, timer)
        if fold not in samplers:
            samplers[fold] = DP.PhraseSampler(fold_library(self, fold, True, a.clean_joins), DP.KEY)
        music = self._music(job, timer)
        code, probs = self.encode(music.x)
        probs = {g: float(p) for g, p in zip(DF.MUSIC_GENRES, probs, strict=True)}
        genre = job.genre or max(probs, key=probs.get)
        motion, joins = DP.dance_motion(samplers[fold], code, DF.genre_index(genre),
                                        np.random.default_rng(music.noise_seed),
                                        pin_joins=a.clean_joins)  # fmt: skip
        count(joins)
        return dance_of_phrases(self, job, music, genre, probs, motion)

    def count(joins):
        runs["phrases"] += len(joins)
        runs["continued"] += sum(
            b == a + DP.PHRASE for (_, a), (_, b) in zip(joins, joins[1:], strict=False)
        )

    if a.motion_space or a.clean_joins:
        E.DanceEngine.predict = predict
    else:
        E.DanceEngine.rollout = rollout
    if a.no_foot_cleanup:
        dance = E.DanceEngine._dance

        def without_cleanup(self, job, music, out, timer):
            return dance(self, replace(job, foot_cleanup=False), music, out, timer)

        E.DanceEngine._dance = without_cleanup
    ED.main(["--held-out-only", "--whole-songs", "--fold-models", "runs/eval/models-fold1",
             "--first-seed", str(a.first_seed), "--json", a.json])  # fmt: skip
    print(json.dumps({"phrases": runs["phrases"], "joins_that_continue_the_same_dance":
                      runs["continued"], "tango_by_the_network":
                      runs["tango by the network"]}))  # fmt: skip


if __name__ == "__main__":
    main()

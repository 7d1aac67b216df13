"""The dance family (jacob2019, made to work): music in, a dance for the whole song out.

A request's song goes: decoded samples -> per-frame features at 30 fps for its whole decoded
length (``motion.audio``; beats tracked on the song itself) -> standardised -> ``audio``
graph (code per frame, genre probabilities) -> the ``step`` graph frame by frame, feeding
back its own pose (LSTM states explicit), from a seeded start pose with seeded noise on the
fed-back pose -> raw features -> Butterworth low-pass -> standstills filled -> canonical
motion (root integrated) -> foot contacts pinned by IK -> time warp putting its kinematic
beats on the song's pulses (``motion.beat_warp``) -> the requested frame rate. Routes
retarget it when asked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from motion import audio
from motion import beat_warp as BW
from motion import dance_features as DF
from motion.skeleton import Motion
from service.engines import register_engine
from service.engines.base import Engine
from service.metrics import StageTimer

BUCKET = 256  # audio frames: the audio graph runs at multiples of this
NOISE = 0.05  # std of the seeded noise on the fed-back pose (standardised units)


@dataclass
class DanceResult:
    """A generated dance on the canonical skeleton at 30 fps, with what the engine decided."""

    motion: Motion
    genre: str
    genre_probs: dict[str, float]
    genre_given: bool
    tempo: float
    beats: np.ndarray
    bas: float
    bas_chance: float
    warnings: list[str] = field(default_factory=list)


class DanceEngine(Engine):
    family: ClassVar[str] = "dance"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": BUCKET}
    # the rollout runs the step graph once per frame: sleeping threads cost it 10-20%
    spinning_graphs: ClassVar[frozenset[str]] = frozenset({"step"})

    def load_assets(self) -> None:
        arrays = self.load_npz(self.entry.extra["stats"])
        self.stats = DF.DanceStats.from_arrays(arrays)
        self.start_poses = np.asarray(arrays["start_poses"], np.float32)
        self.hidden = int(self.entry.extra["hidden"])
        if list(self.entry.extra.get("genres", DF.GENRES)) != list(DF.GENRES):
            raise ValueError("the bundle's genres differ from motion.dance_features.GENRES")

    def styles(self) -> list[dict[str, Any]]:
        return [{"name": g, "music": g in DF.MUSIC_GENRES} for g in DF.GENRES]

    # --- network --------------------------------------------------------------------------

    def encode(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised audio ``(F, A)`` -> code ``(F, code)`` and genre probabilities ``(4,)``
        (over the unpadded frames: the graph's own mean includes padding, so the head is
        applied to codes of an edge-padded bucket; the difference is a few frames)."""
        frames = len(x)
        total = max(BUCKET, -(-frames // BUCKET) * BUCKET)
        padded = np.pad(x, ((0, total - frames), (0, 0)), mode="edge")[None]
        code, probs = self.run("audio", {"audio": padded.astype(np.float32)})
        return code[0, :frames], probs[0]

    def rollout(
        self, code: np.ndarray, genre: np.ndarray, start: np.ndarray, seed: int
    ) -> np.ndarray:
        """Standardised poses ``(F, M)``: frame 0 is ``start``, each next one from the step
        graph fed its own (seeded-noisy) output."""
        rng = np.random.default_rng(seed)
        frames = len(code)
        out = np.empty((frames, DF.MOTION_CHANNELS), np.float32)
        out[0] = start
        zeros = np.zeros((1, self.hidden), np.float32)
        feeds = {"genre": genre[None].astype(np.float32), "h1": zeros, "c1": zeros,
                 "h2": zeros, "c2": zeros}  # fmt: skip
        prev = start[None].astype(np.float32)
        noise = (NOISE * rng.standard_normal((frames, DF.MOTION_CHANNELS))).astype(np.float32)
        noise[:, DF.CONTACTS] = 0.0
        session = self.sessions["step"]
        for t in range(1, frames):
            feeds["code"] = code[t : t + 1]
            feeds["prev"] = prev + noise[t]
            pose, feeds["h1"], feeds["c1"], feeds["h2"], feeds["c2"] = session.run(None, feeds)
            out[t] = pose[0]
            prev = pose
        return out

    # --- the whole request ------------------------------------------------------------------

    def dance(
        self,
        samples: np.ndarray,
        sr: int,
        timer: StageTimer,
        *,
        genre: str | None = None,
        seed: int = 0,
        beat_warp: bool = True,
        foot_cleanup: bool = True,
    ) -> DanceResult:
        """A canonical motion at 30 fps covering the decoded ``samples (N,)`` at ``sr``."""
        warnings: list[str] = []
        with timer.stage("features"):
            frames = max(2, math.ceil(len(samples) / sr * DF.FPS - 1e-9))
            feats = audio.frame_features(samples, sr, DF.FPS, frames)
            x = self.stats.normalize_audio(feats.matrix())
        with timer.stage("audio_network"):
            code, probs = self.encode(x)
        prob_map = {g: round(float(p), 4) for g, p in zip(DF.MUSIC_GENRES, probs, strict=True)}
        given = genre is not None
        if genre is None:
            genre = DF.MUSIC_GENRES[int(np.argmax(probs))]
            warnings.append(f"genre not given: predicted {genre} (p = {prob_map[genre]:.2f})")
        vector = DF.genre_vector(genre)
        if feats.tempo <= 0:
            warnings.append("no beat found in the music: the dance is not beat-aligned")
        rng = np.random.default_rng(seed)
        start = self.stats.normalize_motion(self.start_poses[rng.integers(len(self.start_poses))])
        with timer.stage("step_network"):
            z = self.rollout(code, vector, start, int(rng.integers(2**31)))
        with timer.stage("decode"):
            raw = DF.smooth_features(self.stats.denormalize_motion(z))
            _, motion = DF.keep_moving(raw, feats.playing)
        beats = feats.beats
        if foot_cleanup:  # before the warp, which keeps still feet still and sets the timing
            with timer.stage("foot_cleanup"):
                motion = DF.clean_feet(motion)
        if beat_warp and len(beats) >= 2:
            with timer.stage("beat_warp"):
                motion = BW.warp_to_beats(motion, feats.pulses).motion
        bas, chance = BW.alignment(motion, beats)
        return DanceResult(
            motion, genre, prob_map, given, float(feats.tempo), beats, bas, chance, warnings
        )


register_engine("dance", DanceEngine)

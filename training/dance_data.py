"""The dance network's training data: Dance with Melody dances on their songs' clocks with
their music's features, CMU dances with silent audio, and random windows of them
(``training.dance`` trains on them; ``python -m training.dance`` explains the choices)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from motion import dance_features as DF
from motion import kinematics as K
from training.data import save_npz

PREPARED_VERSION = "1"


@dataclass
class Sequence:
    """One dance as network inputs: raw ``audio (F, AUDIO_CHANNELS)`` and ``motion (F,
    MOTION_CHANNELS)`` at 30 fps on the song's clock, genre index, whether it has music and
    whether its beat phase is trusted."""

    name: str
    genre: int
    audio: np.ndarray
    motion: np.ndarray
    has_music: bool
    trusted: bool

    @property
    def frames(self) -> int:
        return len(self.motion)


def silent_audio(frames: int) -> np.ndarray:
    """Audio input ``(frames, AUDIO_CHANNELS)`` of silence (beat unknown)."""
    row = DF.song_features(np.zeros(2205, np.float32), 22050, 1)[0]
    return DF.drop_beats(np.repeat(row[None], frames, axis=0))


def retime(motion, rate: float):
    """``motion`` (30 fps, motion clock) resampled onto the song's clock: frame ``j`` shows
    motion time ``j / 30 / rate``."""
    count = int(np.floor((motion.num_frames - 1) * rate)) + 1
    return K.resample_at(motion, np.arange(count) / rate, motion.fps)


def _prepare_dwm(clip, alignment, root: Path) -> Sequence:
    from motion import audio_decode
    from training.dance_alignment import analyse_music

    motion = retime(clip.motion, alignment.rate)
    folder = root / Path(clip.extra["audio"]).parent
    music = analyse_music(folder)
    samples, sr = audio_decode.decode(folder / "audio.mp3")
    x = DF.song_features(
        samples,
        sr,
        motion.num_frames,
        offset=alignment.offset,
        beats=music["beats"],
        tempo=float(music["tempo"]),
    )
    if not alignment.trusted:
        x = DF.drop_beats(x)
    return Sequence(
        clip.name,
        DF.genre_index(clip.genre),
        x,
        DF.encode(motion).features,
        True,
        alignment.trusted,
    )


def prepare(log=print) -> list[Sequence]:
    """Every training/validation sequence, cached in the data cache (rebuilt when the clips,
    the alignment table or :data:`PREPARED_VERSION` change)."""
    from training import dance_alignment as DA
    from training.data import cache_dir, data_dir, load_cmu_dance, load_dance_with_melody

    table = DA.load_table()
    dwm, cmu = load_dance_with_melody(), load_cmu_dance()
    key = hashlib.sha256(
        json.dumps(
            [PREPARED_VERSION, table["dances"], [(c.name, c.num_frames) for c in dwm + cmu]],
            sort_keys=True,
        ).encode()
    ).hexdigest()[:16]
    path = cache_dir() / f"dance_prepared_{key}.npz"
    if path.exists():
        return load_prepared(path)
    seqs = []
    for clip in dwm:
        alignment = DA.alignment_for(clip.name, table)
        if alignment is None:
            log(f"{clip.name}: not in the alignment table, skipped")
            continue
        seqs.append(_prepare_dwm(clip, alignment, data_dir()))
        log(f"prepared {clip.name} ({alignment.verdict}, rate {alignment.rate:.4f})")
    for clip in cmu:
        if clip.genre not in DF.GENRES:
            continue
        motion = DF.encode(clip.motion).features
        seqs.append(
            Sequence(
                clip.name, DF.genre_index(clip.genre), silent_audio(len(motion)), motion,
                False, False,
            )
        )  # fmt: skip
    save_prepared(path, seqs)
    return seqs


def save_prepared(path: Path, seqs: list[Sequence], half: bool = False) -> None:
    """``seqs`` in one file (``load_prepared`` reads it back). ``half``: as float16, for a
    copy carried to a lent machine (``training.carry dance``: 18 MB against 39 MB)."""
    dtype = np.float16 if half else np.float32
    arrays = {}
    for i, s in enumerate(seqs):
        arrays[f"a{i}"], arrays[f"m{i}"] = s.audio.astype(dtype), s.motion.astype(dtype)
    meta = [
        {"name": s.name, "genre": s.genre, "music": s.has_music, "trusted": s.trusted} for s in seqs
    ]
    save_npz(path, meta=np.array(json.dumps(meta)), **arrays)


def load_prepared(path: Path) -> list[Sequence]:
    """The sequences ``save_prepared`` wrote to ``path``, as float32."""
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        return [
            Sequence(m["name"], m["genre"], z[f"a{i}"].astype(np.float32, copy=False),
                     z[f"m{i}"].astype(np.float32, copy=False), m["music"], m["trusted"])
            for i, m in enumerate(meta)
        ]  # fmt: skip


def start_poses(seqs: list[Sequence], count: int = 64, seed: int = 0) -> np.ndarray:
    """Raw motion frames ``(count, MOTION_CHANNELS)`` spread over the training dances with
    music: the service's seeded starting poses."""
    rng = np.random.default_rng(seed)
    pool = [s for s in seqs if s.has_music]
    picks = []
    for i in range(count):
        s = pool[i % len(pool)]
        picks.append(s.motion[rng.integers(0, s.frames)])
    poses = np.stack(picks).astype(np.float32)
    poses[:, DF.VELOCITY] = 0.0
    poses[:, DF.TURN] = 0.0
    return poses


class WindowSampler:
    """Random windows ``(B, T, ...)`` of normalised training sequences."""

    def __init__(self, seqs, stats: DF.DanceStats, window: int, cmu_share: float, seed: int):
        self.window = window
        self.rng = np.random.default_rng(seed)
        self.music = [s for s in seqs if s.has_music and s.frames > window]
        self.silent = [s for s in seqs if not s.has_music and s.frames > window]
        self.cmu_share = cmu_share if self.silent else 0.0
        self.audio = {id(s): stats.normalize_audio(s.audio) for s in self.music + self.silent}
        self.motion = {id(s): stats.normalize_motion(s.motion) for s in self.music + self.silent}
        self.trusted_index = {id(s): s.trusted for s in self.music}

    def _pick(self, pool):
        weights = np.array([s.frames - self.window for s in pool], dtype=np.float64)
        return pool[self.rng.choice(len(pool), p=weights / weights.sum())]

    def batch(self, size: int, beat_dropout: float = 0.1):
        audio, motion, genre, music = [], [], [], []
        for _ in range(size):
            silent = self.rng.random() < self.cmu_share
            s = self._pick(self.silent if silent else self.music)
            t0 = int(self.rng.integers(0, s.frames - self.window))
            a = self.audio[id(s)][t0 : t0 + self.window].copy()
            if s.has_music and s.trusted and self.rng.random() < beat_dropout:
                a[:, DF.BEAT_COLUMNS] = 0.0
            audio.append(a)
            motion.append(self.motion[id(s)][t0 : t0 + self.window])
            genre.append(s.genre)
            music.append(s.has_music)
        return (
            torch.from_numpy(np.stack(audio)),
            torch.from_numpy(np.stack(motion)),
            torch.tensor(genre),
            torch.tensor(music),
        )

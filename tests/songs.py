"""Synthetic songs for tests and benchmarks: a drum pattern, a bass line and chords at a
steady tempo, so beats are there to find, encoded to any format soundfile writes."""

from __future__ import annotations

import io

import numpy as np
import soundfile

SR = 22050
BLOCK = 8192  # samples per write


def song(seconds: float, bpm: float = 112.0, sr: int = SR, seed: int = 0) -> np.ndarray:
    """Mono float32 samples: kick on every beat, snare on 2 and 4, hi-hat on eighths,
    a bass note per beat and a chord per bar, changing every four bars."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds * sr))
    t = np.arange(n) / sr
    y = np.zeros(n, np.float64)
    beat = 60.0 / bpm
    chords = [(220.0, 277.2, 329.6), (196.0, 246.9, 293.7), (174.6, 220.0, 261.6),
              (196.0, 246.9, 311.1)]  # fmt: skip

    def hit(start: float, length: float, wave) -> None:
        i = int(start * sr)
        m = min(int(length * sr), n - i)
        if m > 0:
            k = np.arange(m) / sr
            y[i : i + m] += wave(k)

    for b, onset in enumerate(np.arange(0.0, seconds, beat)):
        bar = b // 4
        root, third, fifth = chords[(bar // 4) % len(chords)]
        hit(onset, 0.25, lambda k: 0.9 * np.sin(2 * np.pi * 60 * k * (1 + 2 * np.exp(-k * 40)))
            * np.exp(-k * 18))  # fmt: skip
        if b % 2 == 1:
            hit(onset, 0.2, lambda k: 0.35 * rng.standard_normal(len(k)) * np.exp(-k * 25))
        for half in (0.0, beat / 2):
            hit(onset + half, 0.05, lambda k: 0.12 * rng.standard_normal(len(k)) * np.exp(-k * 90))
        hit(onset, beat, lambda k, f=root / 2: 0.25 * np.sin(2 * np.pi * f * k) * np.exp(-k * 3))
        if b % 4 == 0:
            hit(onset, 4 * beat, lambda k, c=(root, third, fifth): 0.08 * sum(
                np.sin(2 * np.pi * f * k) for f in c) * np.exp(-k * 0.6))  # fmt: skip
    y += 0.01 * np.sin(2 * np.pi * 110 * t)
    return (0.8 * y / max(np.abs(y).max(), 1e-9)).astype(np.float32)


def encoded(samples: np.ndarray, fmt: str, sr: int = SR) -> bytes:
    """``samples`` as a WAV, FLAC, OGG (Vorbis) or MP3 file's bytes."""
    buf = io.BytesIO()
    subtype = {"OGG": "VORBIS", "MP3": "MPEG_LAYER_III"}.get(fmt.upper())
    # in blocks: libsndfile's Vorbis encoder crashes on one long write
    with soundfile.SoundFile(buf, "w", sr, 1, subtype=subtype, format=fmt) as f:
        block = BLOCK if subtype == "VORBIS" else len(samples) or 1
        for i in range(0, len(samples), block):
            f.write(samples[i : i + block])
    return buf.getvalue()

"""Synthetic songs for tests, benchmarks and the dance evaluation.

:func:`song`: a drum pattern, a bass line and chords at a steady tempo, encoded to any format
soundfile writes (:func:`encoded`). :func:`beat_song`: the beat test set, drum patterns
whose beat and downbeat times are known (:data:`PATTERNS`, :func:`beat_test_set`).
"""

from __future__ import annotations

import io
from dataclasses import dataclass

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


# --------------------------------------------------------------------------- beat test set

PATTERNS = (
    "four_on_the_floor",
    "backbeat",
    "swing",
    "triplet",
    "half_time",
    "tempo_change",
    "quiet_intro",
    "break",
    "waltz",
)
"""The beat test set's drum patterns (see :func:`beat_song`)."""
TEMPI = (70.0, 95.0, 124.0, 150.0, 180.0)
"""Tempi (bpm) every pattern is played at; ``tempo_change`` goes from each to 1.25 times it
(or 0.75 times it above 140 bpm)."""
INTRO_SECONDS = 8.0
BREAK_SECONDS = (24.0, 36.0)  # the break's start and end in ``break`` (no drums)
CHANGE_SECONDS = 30.0  # where ``tempo_change`` jumps


@dataclass(frozen=True)
class BeatSong:
    """A generated song and its known beats: ``samples (N,)`` at ``sr``; ``beats (B,)`` and
    ``downbeats (D,)`` in seconds (the beats a listener taps: every quarter note, from the
    first one the drums play; through a break they go on on the same grid). The music
    never stops: intros and breaks keep chords."""

    name: str
    pattern: str
    bpm: float
    samples: np.ndarray
    sr: int
    beats: np.ndarray
    downbeats: np.ndarray


def _kick(k):  # a pitched-down sine thump: energy below 150 Hz
    return 0.9 * np.sin(2 * np.pi * 55 * k * (1 + 2.5 * np.exp(-k * 35))) * np.exp(-k * 14)


def _snare(rng):
    def wave(k):
        body = 0.35 * np.sin(2 * np.pi * 190 * k) * np.exp(-k * 30)
        return body + 0.45 * rng.standard_normal(len(k)) * np.exp(-k * 22)

    return wave


def _hat(rng, level):  # bright: first difference of noise (energy rises with frequency)
    def wave(k):
        noise = np.diff(rng.standard_normal(len(k) + 1))
        return level * noise * np.exp(-k * 60)

    return wave


def _bass(freq):
    return lambda k: 0.3 * np.sin(2 * np.pi * freq * k) * np.exp(-k * 4)


def _chord(freqs, level=0.07):
    return lambda k: level * sum(np.sin(2 * np.pi * f * k) for f in freqs) * np.exp(-k * 0.4)


CHORDS = ((220.0, 277.2, 329.6), (196.0, 246.9, 293.7), (174.6, 220.0, 261.6),
          (196.0, 246.9, 311.1))  # fmt: skip


def beat_song(pattern: str, bpm: float, seconds: float = 60.0, sr: int = SR, seed: int = 0):
    """One song of the beat test set (a :class:`BeatSong`), 4/4 but for ``waltz``, one chord
    per bar:

    - ``four_on_the_floor``: a kick on every beat, a loud open hi-hat halfway between;
    - ``backbeat``: kick on 1 and 3, snare on 2 and 4, hi-hat on the eighths, bass on 1 and 3;
    - ``swing``: the backbeat with the hi-hat's second eighth at two thirds of the beat;
    - ``triplet``: kick on 1 and 3, snare on 2 and 4, hi-hat on every triplet eighth (three
      to a beat), bass on the last triplet of each beat;
    - ``half_time``: hi-hat on every beat, kick on 1 and snare on 3 (a bar sounds like two
      beats of a song at half the tempo);
    - ``tempo_change``: the backbeat jumping at :data:`CHANGE_SECONDS` to 1.25 times ``bpm``
      (0.75 times above 140 bpm);
    - ``quiet_intro``: :data:`INTRO_SECONDS` of quiet chords, then four on the floor (beats
      from the first kick);
    - ``break``: the backbeat with no drums between :data:`BREAK_SECONDS` (chords and bass
      go on; so do the known beats);
    - ``waltz``: 3/4, kick and bass on 1, a chord stab and a snare on 2 and 3, the hi-hat on
      every eighth (as loud as a waltz's pianos and strings make its half-beats).
    """
    if pattern not in PATTERNS:
        raise ValueError(f"unknown pattern {pattern!r}; patterns are {PATTERNS}")
    rng = np.random.default_rng(seed)
    n = int(round(seconds * sr))
    y = np.zeros(n, np.float64)

    def hit(start: float, length: float, wave) -> None:
        i = int(round(start * sr))
        m = min(int(length * sr), n - i)
        if m > 0 and i >= 0:
            y[i : i + m] += wave(np.arange(m) / sr)

    # the beat grid: one tempo, or two for tempo_change
    start = INTRO_SECONDS if pattern == "quiet_intro" else 0.0
    if pattern == "tempo_change":
        second = bpm * (0.75 if bpm > 140 else 1.25)
        first = np.arange(0.0, CHANGE_SECONDS, 60.0 / bpm)
        later = np.arange(first[-1] + 60.0 / bpm, seconds, 60.0 / second)
        beats = np.concatenate([first, later])
    else:
        beats = np.arange(start, seconds, 60.0 / bpm)
    beats = beats[beats < seconds - 0.05]
    period = np.diff(np.append(beats, beats[-1] + (beats[-1] - beats[-2])))
    drums = np.ones(len(beats), bool)
    if pattern == "break":
        drums = (beats < BREAK_SECONDS[0]) | (beats >= BREAK_SECONDS[1])
    if pattern == "quiet_intro":
        bar = 4 * 60.0 / bpm
        for i, t in enumerate(np.arange(0.0, start, bar)):
            hit(t, bar, _chord(CHORDS[i % 4], 0.02))
    if pattern == "waltz":
        for b, (t, p) in enumerate(zip(beats, period, strict=True)):
            chord = CHORDS[(b // 3) % 4]
            if b % 3 == 0:
                hit(t, 3 * p, _chord(chord))  # the bar's chord rings on: no silence
                hit(t, 0.3, _kick)
                hit(t, 3 * p, _bass(chord[0] / 2))
            else:
                hit(t, 0.6 * p, _chord(chord, 0.12))
                hit(t, 0.15, _snare(rng))
            for s in (0.0, 0.5):
                hit(t + s * p, 0.05, _hat(rng, 0.3))
        return _finish(pattern, bpm, y, rng, sr, beats, beats[::3])
    for b, (t, p) in enumerate(zip(beats, period, strict=True)):
        in_bar = b % 4
        if in_bar == 0:
            chord = CHORDS[(b // 4) % 4]
            hit(t, 4 * p, _chord(chord))
        if pattern in ("four_on_the_floor", "quiet_intro"):
            hit(t, 0.3, _kick)
            hit(t + p / 2, 0.12, _hat(rng, 0.6))
            continue
        if pattern == "half_time":
            hit(t, 0.05, _hat(rng, 0.35))
            if in_bar == 0:
                hit(t, 0.3, _kick)
            elif in_bar == 2:
                hit(t, 0.25, _snare(rng))
            continue
        # backbeat, swing, triplet, tempo_change, break
        if in_bar in (0, 2):
            hit(t, p, _bass(CHORDS[(b // 4) % 4][0] / 2))
        if not drums[b]:
            continue
        if in_bar in (0, 2):
            hit(t, 0.3, _kick)
        else:
            hit(t, 0.25, _snare(rng))
        if pattern == "swing":
            subdivisions = (0.0, 2.0 / 3.0)
        elif pattern == "triplet":
            subdivisions = (0.0, 1.0 / 3.0, 2.0 / 3.0)
            hit(t + 2.0 * p / 3.0, p / 3.0, _bass(CHORDS[(b // 4) % 4][0] / 2))
        else:
            subdivisions = (0.0, 0.5)
        for s in subdivisions:
            hit(t + s * p, 0.05, _hat(rng, 0.3))
    return _finish(pattern, bpm, y, rng, sr, beats, beats[::4])


def _finish(pattern, bpm, y, rng, sr, beats, downbeats) -> BeatSong:
    y = y + 0.003 * rng.standard_normal(len(y))  # a noise floor: no digital silence anywhere
    samples = (0.8 * y / max(np.abs(y).max(), 1e-9)).astype(np.float32)
    return BeatSong(f"{pattern}_{bpm:g}", pattern, float(bpm), samples, sr, beats, downbeats)


def beat_test_set(seconds: float = 60.0, tempi=TEMPI, patterns=PATTERNS) -> list[BeatSong]:
    """Every pattern at every tempo (8 x 5 songs of ``seconds`` by default)."""
    return [beat_song(p, bpm, seconds) for p in patterns for bpm in tempi]

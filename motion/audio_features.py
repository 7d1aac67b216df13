"""Audio features for dance, one row per motion frame, computed alike in training and serving.

Pipeline: :func:`motion.audio_decode.decode` (any wav/flac/ogg/mp3 to mono float32) ->
:func:`~motion.audio_decode.check_not_silent` -> :func:`frame_features` (resamples to
:data:`~motion.spectral.FEATURE_SR`, then one feature row per motion frame) ->
:meth:`AudioFeatures.matrix` (``(F, FEATURE_DIM)`` float32 for networks).

Timing convention: motion frame ``i`` is the instant ``i / fps`` seconds after the start of
the audio, and its spectral features come from an ``N_FFT``-sample Hann window centred on
that instant (the window's centre is ``round(i * FEATURE_SR / fps)``, so alignment is exact
to half a sample at any fps, integral hop or not). Beats are tracked once, on a fine onset
envelope at ``ONSET_FRAME_RATE`` (:mod:`motion.beat_tracking`), whatever the fps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from motion.audio_decode import SILENCE_DBFS
from motion.beat_tracking import (
    GENRE_TEMPO,
    Tempo,
    at_level,
    beat_phase,
    downbeats,
    pulses,
    tempo_curve,
    track_beats,
)
from motion.spectral import (
    FEATURE_SR,
    N_MELS,
    ONSET_FRAME_RATE,
    SPECTRAL_COLUMNS,
    beat_envelope,
    beat_levels,
    onset_from_log_mel,
    onset_mel_power,
    power_db,
    prepare_samples,
    spectral_frames,
)

MATRIX_COLUMNS = (
    *(f"mel_{k}" for k in range(N_MELS)),
    *SPECTRAL_COLUMNS,
    "onset",
    "beat_sin",
    "beat_cos",
)
"""Columns of :meth:`AudioFeatures.matrix`: log-mel (64), spectral summary (30), onset
strength (1), then beat phase as ``sin``/``cos`` of ``2 pi phase`` (2): no jump at the beat."""
FEATURE_DIM = len(MATRIX_COLUMNS)
"""Width D of :meth:`AudioFeatures.matrix` (97)."""


@dataclass(frozen=True, eq=False)
class AudioFeatures:
    """Audio features with one row per motion frame (``F`` frames at ``fps``).

    ``mel`` ``(F, N_MELS)`` log-mel power in dB (0 dB: a full-scale sine's STFT bin; the
    Slaney-normalised bands then sit lower, about -18 dB for a full-scale 1 kHz sine; floor
    DB_FLOOR); ``spectral`` ``(F, len(SPECTRAL_COLUMNS))``; ``onset`` ``(F,)`` onset strength
    (the largest value of the fine envelope within half a frame of the frame's instant);
    ``beat_phase`` ``(F,)`` in ``[0, 1)``; ``beats`` ``(B,)`` beat times in seconds
    (:func:`motion.spectral.beat_onset_strength`, :func:`motion.beat_tracking.track_beats`);
    ``tempo`` in bpm (0 when no beat was found); ``downbeats`` ``(D,)`` the beats that start
    a bar of ``beats_per_bar`` (:func:`motion.beat_tracking.downbeats`; empty and 0 when the
    song has under two bars); ``pulses`` ``(P,)`` the beats and, where the song accents them
    as much, the half-beats (:func:`motion.beat_tracking.pulses`: what a dance should land
    on); ``beat_onset`` the envelope they were tracked on, at ``ONSET_FRAME_RATE``, and
    ``tempo_curve`` its tempo (:meth:`for_genre` tracks it again at a genre's level).
    Values are in the units stated, not normalised: networks normalise them with
    statistics saved at training time.
    """

    fps: float
    mel: np.ndarray
    spectral: np.ndarray
    onset: np.ndarray
    beat_phase: np.ndarray
    beats: np.ndarray
    tempo: float
    downbeats: np.ndarray
    beats_per_bar: int
    pulses: np.ndarray
    beat_onset: np.ndarray
    tempo_curve: Tempo

    @property
    def num_frames(self) -> int:
        return len(self.onset)

    @property
    def playing(self) -> np.ndarray:
        """``(F,)`` bool: the music sounds at the frame (RMS above :data:`SILENCE_DBFS`)."""
        return self.spectral[:, SPECTRAL_COLUMNS.index("rms_db")] > SILENCE_DBFS

    def for_genre(self, genre: str | None) -> tuple[float, np.ndarray, np.ndarray]:
        """``(tempo, beats, pulses)`` at the metrical level a dancer of ``genre`` steps
        (:func:`motion.beat_tracking.genre_prior`; the features' own for None)."""
        if genre is None:
            return self.tempo, self.beats, self.pulses
        tempo, beats = self.tempo, self.beats
        if genre in GENRE_TEMPO:
            level = at_level(self.tempo_curve, GENRE_TEMPO[genre], ONSET_FRAME_RATE)
            if level is not self.tempo_curve:
                tempo, beats = track_beats(self.beat_onset, ONSET_FRAME_RATE, tempo=level)
        return tempo, beats, pulses(beats, self.beat_onset, genre=genre)

    def matrix(self) -> np.ndarray:
        """``(F, FEATURE_DIM)`` float32 laid out as MATRIX_COLUMNS."""
        angle = 2.0 * np.pi * self.beat_phase.astype(np.float64)
        return np.column_stack(
            [self.mel, self.spectral, self.onset, np.sin(angle), np.cos(angle)]
        ).astype(np.float32)


def frame_features(
    samples: np.ndarray, sr: int, fps: float, num_frames: int | None = None
) -> AudioFeatures:
    """Features of mono ``samples`` ``(N,)`` at ``sr`` Hz for motion at ``fps``.

    ``num_frames`` defaults to ``ceil(N / sr * fps)``: every instant of the audio is covered.
    Frames past the end of the audio see silence. Deterministic: the same samples give the
    same features at training and serving.
    """
    fps = float(fps)
    if not (math.isfinite(fps) and 0 < fps <= 1000):
        raise ValueError(f"fps must be in (0, 1000], got {fps}")
    y = prepare_samples(samples, sr)
    if num_frames is None:
        num_frames = math.ceil(len(np.asarray(samples)) / sr * fps - 1e-9)
    if num_frames < 0:
        raise ValueError(f"num_frames must be >= 0, got {num_frames}")
    centres = np.round(np.arange(num_frames) * (FEATURE_SR / fps)).astype(np.int64)
    mel, spectral = spectral_frames(y, centres)
    onset_mel = onset_mel_power(y)
    envelope = onset_from_log_mel(power_db(onset_mel), np.mean)
    levels = beat_levels(onset_mel)
    beat_onset = beat_envelope(onset_mel, levels)
    estimate = tempo_curve(beat_onset, ONSET_FRAME_RATE)
    tempo, beats = track_beats(beat_onset, ONSET_FRAME_RATE, tempo=estimate)
    bar_starts, bar = downbeats(beats, onset_mel, levels=levels)
    onset = _onset_at_frames(envelope, num_frames, fps)
    phase = beat_phase(beats, num_frames, fps, period=60.0 / tempo if tempo > 0 else None)
    return AudioFeatures(
        fps=fps,
        mel=mel,
        spectral=spectral,
        onset=onset,
        beat_phase=phase,
        beats=beats,
        tempo=tempo,
        downbeats=bar_starts,
        beats_per_bar=bar,
        pulses=pulses(beats, beat_onset),
        beat_onset=beat_onset,
        tempo_curve=estimate,
    )


def _onset_at_frames(envelope: np.ndarray, num_frames: int, fps: float) -> np.ndarray:
    """``(num_frames,)``: per motion frame, the max of the envelope over the frame's span
    ``[t - 0.5 / fps, t + 0.5 / fps)`` and of its linear interpolation at ``t``, so that a
    peak is never lost between frames (at any fps above or below the envelope's rate)."""
    env_times = np.arange(len(envelope)) / ONSET_FRAME_RATE
    times = np.arange(num_frames) / fps
    value = np.interp(times, env_times, envelope, right=0.0)
    edges = np.searchsorted(env_times, (np.arange(num_frames + 1) - 0.5) / fps)
    padded = np.append(envelope, 0.0)  # reduceat needs every index in range
    span_max = np.maximum.reduceat(padded, np.minimum(edges, len(envelope)))[:num_frames]
    non_empty = edges[1:] > edges[:-1]
    value[non_empty] = np.maximum(value[non_empty], span_max[non_empty])
    return value.astype(np.float32)

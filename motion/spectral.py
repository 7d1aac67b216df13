"""Spectra of a song: the analysis constants, mel and chroma filterbanks, per-window spectral
summaries and the onset envelopes that beats are tracked on.

Levels are absolute (power spectra scaled so that a full-scale sine's bin is 0 dB, floored
at :data:`DB_FLOOR`), not relative to the loudest frame, so a window's features do not
depend on what else is in the excerpt. Every analysis runs on audio resampled to
:data:`FEATURE_SR` (:func:`prepare_samples`).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from motion.audio_decode import check_sample_values, resample
from motion.errors import MotionError

FEATURE_SR = 22050
"""Analysis sample rate (Hz): every feature is computed from audio resampled to this."""
N_FFT = 2048
"""STFT window length in samples at FEATURE_SR (93 ms, 10.8 Hz bins)."""
ONSET_HOP = 512
"""Hop (samples at FEATURE_SR) of the onset envelope used for beat tracking."""
ONSET_FRAME_RATE = FEATURE_SR / ONSET_HOP
"""Frames per second of the onset envelope that :func:`motion.beat_tracking.track_beats` reads
(about 43.07)."""
N_MELS = 64
"""Mel bands of the ``mel`` feature (Slaney mel scale and area normalisation, 0 Hz to
FEATURE_SR / 2)."""
ONSET_N_MELS = 128
"""Mel bands of the onset envelope: librosa's 128 (a median over 64 bands tracks worse)."""
N_MFCC = 13
CHROMA_FMIN, CHROMA_FMAX = 65.4, 4186.0
"""Chroma uses STFT bins from C2 to C8 only; below C2 bins are wider than a semitone."""
DB_FLOOR = -100.0
"""Lowest level in dB any mel band or RMS may have (0 dB: a full-scale sine's STFT bin)."""

PITCH_CLASSES = ("C", "C#", "D", "D#", "E", "F", "F#", "G", "G#", "A", "A#", "B")
SPECTRAL_COLUMNS = (
    *(f"mfcc_{k}" for k in range(N_MFCC)),
    *(f"chroma_{p}" for p in PITCH_CLASSES),
    "centroid",
    "bandwidth",
    "rolloff",
    "flatness",
    "rms_db",
)
"""Columns of ``AudioFeatures.spectral``: MFCCs (DCT-II of the log-mel), chroma (energy per
pitch class, max-normalised per frame), centroid, bandwidth and 85 % rolloff (as fractions of
the Nyquist frequency), spectral flatness (0..1) and the Hann-weighted RMS in dBFS (a
full-scale sine is -3 dB). This is the hand-made acoustic summary that jacob2019 weighs
against raw STFT input (MFCC and chroma as in Tang et al. 2018, whose data we use); the
STFT itself reaches the network compressed as the log-mel."""

_CHUNK_FRAMES = 1024  # STFT frames per batch: bounds the (chunk, N_FFT) window matrix


def prepare_samples(samples: np.ndarray, sr: int) -> np.ndarray:
    """Validate mono ``(N,)`` audio and resample it to FEATURE_SR (float32)."""
    samples = np.asarray(samples)
    if samples.ndim != 1:
        raise ValueError(f"samples must be mono (N,), got shape {samples.shape}")
    if samples.size == 0:
        raise MotionError("the audio has no samples", kind="unusable")
    check_sample_values(samples)
    if not (isinstance(sr, int | np.integer) and sr > 0):
        raise ValueError(f"sr must be a positive integer, got {sr!r}")
    return resample(samples, int(sr), FEATURE_SR)


def _hz_to_mel(hz: np.ndarray) -> np.ndarray:
    """Slaney's mel scale: linear below 1 kHz, logarithmic above (as librosa, htk=False)."""
    hz = np.asarray(hz, dtype=np.float64)
    mel = hz / (200.0 / 3.0)
    log_region = hz >= 1000.0
    return np.where(
        log_region, 15.0 + np.log(np.maximum(hz, 1e-10) / 1000.0) / (np.log(6.4) / 27.0), mel
    )


def _mel_to_hz(mel: np.ndarray) -> np.ndarray:
    mel = np.asarray(mel, dtype=np.float64)
    return np.where(
        mel >= 15.0, 1000.0 * np.exp((np.log(6.4) / 27.0) * (mel - 15.0)), mel * (200.0 / 3.0)
    )


def mel_filterbank(sr: int = FEATURE_SR, n_fft: int = N_FFT, n_mels: int = N_MELS) -> np.ndarray:
    """Triangular mel filters ``(n_mels, n_fft // 2 + 1)``, Slaney area-normalised."""
    fft_hz = np.arange(n_fft // 2 + 1) * sr / n_fft
    edges_hz = _mel_to_hz(np.linspace(_hz_to_mel(0.0), _hz_to_mel(sr / 2.0), n_mels + 2))
    widths = np.diff(edges_hz)
    rising = (fft_hz[None, :] - edges_hz[:-2, None]) / widths[:-1, None]
    falling = (edges_hz[2:, None] - fft_hz[None, :]) / widths[1:, None]
    weights = np.maximum(0.0, np.minimum(rising, falling))
    weights *= (2.0 / (edges_hz[2:] - edges_hz[:-2]))[:, None]
    return weights


def _chroma_filterbank(sr: int = FEATURE_SR, n_fft: int = N_FFT) -> np.ndarray:
    """``(12, n_fft // 2 + 1)``: each bin C2..C8 shared by its two nearest pitch classes."""
    fft_hz = np.arange(n_fft // 2 + 1) * sr / n_fft
    in_range = (fft_hz >= CHROMA_FMIN) & (fft_hz <= CHROMA_FMAX)
    midi = 69.0 + 12.0 * np.log2(np.maximum(fft_hz, 1e-10) / 440.0)
    distance = (midi[None, :] - np.arange(12)[:, None] + 6.0) % 12.0 - 6.0
    return np.maximum(0.0, 1.0 - np.abs(distance)) * in_range[None, :]


_WINDOW = np.hanning(N_FFT + 1)[:-1].astype(np.float32)  # periodic Hann, as scipy/librosa
_POWER_SCALE = float((_WINDOW.sum() / 2.0) ** 2)  # makes a full-scale sine's bin 0 dB
_WINDOW_ENERGY = float((_WINDOW.astype(np.float64) ** 2).sum())
_MEL = mel_filterbank().astype(np.float32)
_ONSET_MEL = mel_filterbank(n_mels=ONSET_N_MELS).astype(np.float32)
_CHROMA = _chroma_filterbank().astype(np.float32)
_FFT_HZ = np.arange(N_FFT // 2 + 1) * FEATURE_SR / N_FFT


def _power_frames(padded: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Power spectra ``(len(centres), N_FFT // 2 + 1)``, scaled so that a full-scale sine's
    bin is 1, of Hann windows centred on samples ``centres`` of the signal that
    :func:`_pad_for_centres` padded (so in ``padded`` the windows start at ``centres``)."""
    # rows of a strided view: the (frames, N_FFT) index array of a gather cost more than the copy
    windows = np.lib.stride_tricks.sliding_window_view(padded, N_FFT)[centres] * _WINDOW
    spectrum = scipy.fft.rfft(windows, axis=1)
    return (spectrum.real**2 + spectrum.imag**2) / _POWER_SCALE


def _log_mel(power: np.ndarray, filters: np.ndarray = _MEL) -> np.ndarray:
    """``(T, len(filters))`` dB re a full-scale sine, floored at DB_FLOOR."""
    mel = power @ filters.T
    db = 10.0 * np.log10(np.maximum(mel, 10.0 ** (DB_FLOOR / 10.0)))
    return np.maximum(db, DB_FLOOR)  # exactly the floor, float32 rounding notwithstanding


def _pad_for_centres(samples: np.ndarray, last_centre: int) -> np.ndarray:
    """Zero-pad so that a window centred on any sample up to ``last_centre`` fits."""
    half = N_FFT // 2
    tail = max(0, last_centre + half - len(samples)) + half
    return np.concatenate(
        [
            np.zeros(half, np.float32),
            samples.astype(np.float32, copy=False),
            np.zeros(tail, np.float32),
        ]
    )


def spectral_frames(samples: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Log-mel ``(F, N_MELS)`` and spectral summary ``(F, len(SPECTRAL_COLUMNS))`` for Hann
    windows centred on sample indices ``centres`` ``(F,)`` of ``samples`` at FEATURE_SR."""
    num = len(centres)
    mel_out = np.empty((num, N_MELS), np.float32)
    spectral_out = np.empty((num, len(SPECTRAL_COLUMNS)), np.float32)
    if num == 0:
        return mel_out, spectral_out
    padded = _pad_for_centres(samples, int(centres[-1]))
    nyquist = FEATURE_SR / 2.0
    tiny = 1e-12
    for lo in range(0, num, _CHUNK_FRAMES):
        power = _power_frames(padded, centres[lo : lo + _CHUNK_FRAMES])
        log_mel = _log_mel(power)
        mfcc = scipy.fft.dct(log_mel, type=2, norm="ortho", axis=1)[:, :N_MFCC]
        chroma = power @ _CHROMA.T
        chroma /= np.maximum(chroma.max(axis=1, keepdims=True), tiny)
        magnitude = np.sqrt(power)
        mag_sum = magnitude.sum(axis=1)
        has_sound = mag_sum > tiny
        safe_sum = np.where(has_sound, mag_sum, 1.0)
        centroid = (magnitude @ _FFT_HZ) / safe_sum
        spread = (magnitude * (_FFT_HZ[None, :] - centroid[:, None]) ** 2).sum(axis=1)
        bandwidth = np.sqrt(spread / safe_sum)
        cumulative = np.cumsum(magnitude, axis=1)
        rolloff_bin = (cumulative < 0.85 * mag_sum[:, None]).sum(axis=1)
        rolloff = _FFT_HZ[np.minimum(rolloff_bin, len(_FFT_HZ) - 1)]
        floored = np.maximum(power, 1e-10)
        flatness = np.exp(np.log(floored).mean(axis=1)) / floored.mean(axis=1)
        # Parseval over the full spectrum (the half spectrum twice, less DC and Nyquist once)
        full_sum = 2.0 * power.sum(axis=1) - power[:, 0] - power[:, -1]
        mean_square = full_sum * _POWER_SCALE / (N_FFT * _WINDOW_ENERGY)
        rms_db = 10.0 * np.log10(np.maximum(mean_square, 10.0 ** (DB_FLOOR / 10.0)))
        summary = np.column_stack(
            [
                mfcc,
                chroma,
                np.where(has_sound, centroid / nyquist, 0.0),
                np.where(has_sound, bandwidth / nyquist, 0.0),
                np.where(has_sound, rolloff / nyquist, 0.0),
                np.where(has_sound, flatness, 0.0),
                rms_db,
            ]
        )
        mel_out[lo : lo + len(power)] = log_mel
        spectral_out[lo : lo + len(power)] = summary
    return mel_out, spectral_out


# ---------------------------------------------------------------------------------------------
# Onsets and beats

_ONSET_LAG = 1  # onset = rise of the log-mel over one hop (23 ms)
_ONSET_DELAY = 2  # frames the envelope is delayed so its peaks sit on the attacks (see below)


def onset_strength(samples: np.ndarray, sr: int, *, aggregate=np.mean) -> np.ndarray:
    """Onset strength envelope ``(T,)`` of mono ``samples`` ``(N,)``, at ONSET_FRAME_RATE.

    As ``librosa.onset.onset_strength``: the half-wave rectified rise of the log-mel
    spectrum from one frame to the next, aggregated over the mel bands by ``aggregate``
    (``np.mean``; ``np.median``, as ``librosa.beat.beat_track`` uses, is steadier for beat
    tracking), with ``T = 1 + N' // ONSET_HOP`` for ``N'`` samples at FEATURE_SR. Frame
    ``t`` is the instant ``t / ONSET_FRAME_RATE``. The rise between windows centred at frames
    ``t - 2`` and ``t - 1`` is reported at frame ``t``, one frame earlier than librosa: in dB
    the rise is steepest as an attack enters the window, 1 to 2 hops before the window is
    centred on it, and with this delay click tracks peak within half a hop of the clicks.
    """
    return onset_from_log_mel(power_db(onset_mel_power(prepare_samples(samples, sr))), aggregate)


def onset_mel_power(y: np.ndarray) -> np.ndarray:
    """Mel power ``(T, ONSET_N_MELS)`` of ``y`` (FEATURE_SR) at hop ONSET_HOP, windows
    centred (1: a full-scale sine's STFT bin, before the Slaney normalisation)."""
    frames = 1 + len(y) // ONSET_HOP
    centres = np.arange(frames, dtype=np.int64) * ONSET_HOP
    padded = _pad_for_centres(y, int(centres[-1]))
    mel = np.empty((frames, ONSET_N_MELS), np.float32)
    for lo in range(0, frames, _CHUNK_FRAMES):
        power = _power_frames(padded, centres[lo : lo + _CHUNK_FRAMES])
        mel[lo : lo + len(power)] = power @ _ONSET_MEL.T
    return mel


def power_db(mel: np.ndarray) -> np.ndarray:
    db = 10.0 * np.log10(np.maximum(mel, 10.0 ** (DB_FLOOR / 10.0)))
    return np.maximum(db, DB_FLOOR)


def onset_from_log_mel(log_mel: np.ndarray, aggregate) -> np.ndarray:
    return rise_envelope(log_mel, lambda rise: aggregate(rise, axis=1))


def rise_envelope(levels: np.ndarray, combine) -> np.ndarray:
    """``(T,)``: ``combine`` of the half-wave rectified rise ``(T - lag, bands)`` of
    ``levels (T, bands)``, delayed so that frame ``t`` holds the rise from ``t - 2`` to
    ``t - 1`` (see :func:`onset_strength`)."""
    frames = len(levels)
    rise = combine(np.maximum(0.0, levels[_ONSET_LAG:] - levels[:-_ONSET_LAG]))
    envelope = np.concatenate([np.zeros(_ONSET_LAG + _ONSET_DELAY - 1), rise])
    return np.pad(envelope, (0, max(0, frames - len(envelope))))[:frames].astype(np.float32)


BEAT_LOW_HZ = 200.0
"""Mel bands centred below this (kick drum, bass) carry :data:`BEAT_LOW_SHARE` of the beat
envelope, whatever their number (9 of the 128)."""
BEAT_LOW_SHARE = 0.6
BEAT_COMPRESSION = 100.0
"""The beat envelope rises in ``log(1 + BEAT_COMPRESSION * magnitude)``, magnitudes relative
to the song's loudest (99.9th percentile) band: nearly linear for quiet bands, so a band of
noise 60 dB down adds little, unlike a rise in dB, which is the same at every level."""
ONSET_MEL_HZ = (_ONSET_MEL @ _FFT_HZ) / _ONSET_MEL.sum(axis=1)
_BEAT_BAND_WEIGHTS = np.where(
    ONSET_MEL_HZ < BEAT_LOW_HZ,
    BEAT_LOW_SHARE / np.count_nonzero(ONSET_MEL_HZ < BEAT_LOW_HZ),
    (1.0 - BEAT_LOW_SHARE) / np.count_nonzero(ONSET_MEL_HZ >= BEAT_LOW_HZ),
).astype(np.float32)


def beat_onset_strength(samples: np.ndarray, sr: int) -> np.ndarray:
    """The envelope ``(T,)`` that :func:`motion.audio_features.frame_features` tracks beats
    on (ONSET_FRAME_RATE, timed as :func:`onset_strength`): the rise of compressed mel magnitudes (see
    :data:`BEAT_COMPRESSION`), weighted so that the bands below :data:`BEAT_LOW_HZ` count as
    much as :data:`BEAT_LOW_SHARE` of the whole. Kick and bass, which few bands hold, then
    set the beat, not hi-hats, whose bright rise fills most bands: on a kick every beat with
    a hi-hat halfway between, the median rise of dB over bands (librosa's) puts every beat
    on the hi-hats."""
    return beat_envelope(onset_mel_power(prepare_samples(samples, sr)))


def beat_levels(mel: np.ndarray) -> np.ndarray:
    """``log(1 + BEAT_COMPRESSION * magnitude / loudest)`` of mel power ``(T, bands)``."""
    magnitude = np.sqrt(mel)
    scale = float(np.percentile(magnitude, 99.9)) if magnitude.size else 0.0
    return np.log1p((BEAT_COMPRESSION / max(scale, 1e-12)) * magnitude)


def beat_envelope(mel: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    levels = beat_levels(mel) if levels is None else levels
    return rise_envelope(levels, lambda rise: rise @ _BEAT_BAND_WEIGHTS)

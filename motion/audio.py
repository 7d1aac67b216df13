"""Audio for dance: decoding, resampling, per-motion-frame features and beat tracking.

One module so that training and serving compute the same numbers from the same song.
Pipeline: :func:`decode` (any wav/flac/ogg/mp3 to mono float32) -> :func:`check_not_silent`
-> :func:`frame_features` (resamples to :data:`FEATURE_SR`, then one feature row per motion
frame) -> :meth:`AudioFeatures.matrix` (``(F, FEATURE_DIM)`` float32 for networks).

Timing convention: motion frame ``i`` is the instant ``i / fps`` seconds after the start of
the audio, and its spectral features come from an ``N_FFT``-sample Hann window centred on
that instant (the window's centre is ``round(i * FEATURE_SR / fps)``, so alignment is exact
to half a sample at any fps, integral hop or not). Beats are tracked once, on a fine onset
envelope at :data:`ONSET_FRAME_RATE` (about 43 Hz, independent of fps), so the beat times
of a song do not depend on the motion frame rate.

Beat tracking follows Ellis (2007), "Beat tracking by dynamic programming", as librosa
implements it (tempo from the autocorrelation of the onset envelope weighted by a
log-normal prior around 120 bpm; then dynamic programming over beat positions), written in
numpy. Levels are absolute (power spectra scaled so that a full-scale sine's bin is 0 dB,
floored at :data:`DB_FLOOR`), not relative to the loudest frame, so a frame's features do not
depend on what else is in the excerpt.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass

import numpy as np
import scipy.fft
import soundfile
import soxr

from motion.errors import MotionError

FEATURE_SR = 22050
"""Analysis sample rate (Hz): every feature is computed from audio resampled to this."""
N_FFT = 2048
"""STFT window length in samples at FEATURE_SR (93 ms, 10.8 Hz bins)."""
ONSET_HOP = 512
"""Hop (samples at FEATURE_SR) of the onset envelope used for beat tracking."""
ONSET_FRAME_RATE = FEATURE_SR / ONSET_HOP
"""Frames per second of the onset envelope given to :func:`track_beats` (about 43.07)."""
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

ALLOWED_CONTAINERS = ("WAV", "WAVEX", "RF64", "W64", "AIFF", "FLAC", "OGG", "MP3")
"""libsndfile container names :func:`decode` accepts; others it recognises are refused."""
MIN_SAMPLE_RATE, MAX_SAMPLE_RATE = 4000, 384000
MAX_CHANNELS = 32
MAX_ABS_SAMPLE = 1000.0
"""Float samples beyond this (60 dB over full scale) are damage, not headroom."""
SILENCE_DBFS = -60.0
""":func:`check_not_silent` refuses audio whose peak is below this level."""

_READ_BLOCK = 1 << 16  # frames per read: bounds memory and lets max_seconds stop early
_CHUNK_FRAMES = 1024  # STFT frames per batch: bounds the (chunk, N_FFT) window matrix
_SF_ERR_UNSUPPORTED_ENCODING = 4  # libsndfile's public code for a known container, unknown codec


# ---------------------------------------------------------------------------------------------
# Decoding


def decode(
    data: bytes | bytearray | memoryview | str | os.PathLike,
    *,
    max_seconds: float | None = None,
) -> tuple[np.ndarray, int]:
    """Decode a wav/flac/ogg (vorbis, opus)/mp3 file to mono.

    ``data`` is the file's bytes or a path (a missing path raises ``FileNotFoundError``, as
    ``open`` does). Returns ``(samples, sample_rate)``: ``samples`` is ``(N,)`` float32, the
    mean of the channels, and ``N`` counts the frames actually decoded, not what the header
    claims (a truncated file gives the part that is there). Reads in blocks and stops as soon
    as the audio runs past ``max_seconds`` (``MotionError`` kind ``"too-large"``, ``limit``
    set), so an over-long file is never decoded in full. Undecodable data raises kind
    ``"invalid"``; a container libsndfile knows but that we do not accept, or a codec it
    cannot decode, kind ``"unsupported"``; so does an MP3 whose frames hold more audio than
    its header announced (libsndfile cannot decode past that, and we will not silently drop
    the rest). Silence is not checked here: see :func:`check_not_silent`.
    """
    if max_seconds is not None and not max_seconds > 0:
        raise ValueError(f"max_seconds must be positive, got {max_seconds}")
    if isinstance(data, bytes | bytearray | memoryview):
        raw = bytes(data)
        if not raw:
            raise MotionError("the audio is empty (0 bytes)")
        return _decode_file(io.BytesIO(raw), max_seconds)
    with open(data, "rb") as file:
        if os.fstat(file.fileno()).st_size == 0:
            raise MotionError(f"the audio file {os.fspath(data)!r} is empty (0 bytes)")
        return _decode_file(file, max_seconds)


def _decode_file(file, max_seconds: float | None) -> tuple[np.ndarray, int]:
    try:
        sound = soundfile.SoundFile(file)
    except soundfile.LibsndfileError as e:
        raise _open_error(e) from None
    except (soundfile.SoundFileError, RuntimeError, TypeError, ValueError) as e:
        raise MotionError(f"cannot decode the audio: {e}") from None
    with sound:
        container, sr, channels = sound.format, int(sound.samplerate), int(sound.channels)
        if container not in ALLOWED_CONTAINERS:
            raise MotionError(
                f"audio container {container} is not supported: send wav, flac, ogg or mp3",
                kind="unsupported",
            )
        if not MIN_SAMPLE_RATE <= sr <= MAX_SAMPLE_RATE:
            raise MotionError(
                f"sample rate {sr} Hz is not supported "
                f"({MIN_SAMPLE_RATE} to {MAX_SAMPLE_RATE} Hz are)",
                kind="unsupported",
            )
        if not 1 <= channels <= MAX_CHANNELS:
            raise MotionError(
                f"{channels} audio channels are not supported (at most {MAX_CHANNELS})",
                kind="unsupported",
            )
        max_frames = None if max_seconds is None else int(math.floor(max_seconds * sr))
        samples = _read_mono(sound, sr, max_frames, max_seconds)
    if container == "MP3":
        _check_mp3_fully_decoded(file, len(samples), sr)
    if len(samples) == 0:
        raise MotionError("the audio has no samples (0 frames decoded)")
    return samples, sr


def _check_sample_values(samples: np.ndarray) -> None:
    """Refuse NaN, infinity and float samples far beyond full scale (a damaged float file)."""
    if not np.isfinite(samples).all():
        raise MotionError("the audio contains samples that are not finite (NaN or infinity)")
    if samples.size and float(np.max(np.abs(samples))) > MAX_ABS_SAMPLE:
        raise MotionError(
            f"the audio contains samples beyond {MAX_ABS_SAMPLE:g} times full scale "
            "(a damaged float file?)"
        )


def _open_error(e: soundfile.LibsndfileError) -> MotionError:
    if e.code == _SF_ERR_UNSUPPORTED_ENCODING:
        return MotionError(
            f"the audio's encoding is not supported: {e.error_string}", kind="unsupported"
        )
    if e.code == 1:  # SF_ERR_UNRECOGNISED_FORMAT
        return MotionError("not an audio file we can read: send wav, flac, ogg or mp3")
    # code 7 is libsndfile's "file does not exist", which it also says of a broken MP3 stream
    reason = "no decodable audio stream" if e.code == 7 else e.error_string
    return MotionError(f"the audio file is malformed or truncated ({reason})")


def _read_mono(
    sound: soundfile.SoundFile, sr: int, max_frames: int | None, max_seconds: float | None
) -> np.ndarray:
    """Read blocks until the decoder returns no more; mix each block down as it arrives."""
    # buffer_read_into, unlike SoundFile.read, does not stop at the header's frame count.
    block = np.empty((_READ_BLOCK, sound.channels), dtype=np.float32)
    parts: list[np.ndarray] = []
    total = 0
    while True:
        try:
            n = sound.buffer_read_into(block, dtype="float32")
        except (soundfile.SoundFileError, RuntimeError) as e:
            reason = e.error_string if isinstance(e, soundfile.LibsndfileError) else str(e)
            raise MotionError(
                f"the audio stream is corrupt after {total / sr:.2f} s ({reason})"
            ) from None
        if n <= 0:
            break
        with np.errstate(all="ignore"):  # damaged float files: judged just below
            mono = block[:n].mean(axis=1, dtype=np.float32)
        _check_sample_values(mono)
        parts.append(mono)
        total += n
        if max_frames is not None and total > max_frames:
            raise MotionError(
                f"the audio is longer than the limit of {max_seconds:g} s",
                kind="too-large",
                limit=max_seconds,
            )
    if not parts:
        return np.zeros(0, dtype=np.float32)
    return np.concatenate(parts)


# MPEG audio frame header tables: (version, layer) -> kbps by bitrate index.
_MPEG_BITRATES = {
    (1, 1): (0, 32, 64, 96, 128, 160, 192, 224, 256, 288, 320, 352, 384, 416, 448),
    (1, 2): (0, 32, 48, 56, 64, 80, 96, 112, 128, 160, 192, 224, 256, 320, 384),
    (1, 3): (0, 32, 40, 48, 56, 64, 80, 96, 112, 128, 160, 192, 224, 256, 320),
    (2, 1): (0, 32, 48, 56, 64, 80, 96, 112, 128, 144, 160, 176, 192, 224, 256),
    (2, 2): (0, 8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160),
    (2, 3): (0, 8, 16, 24, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160),
}
_MPEG_RATES = {1: (44100, 48000, 32000), 2: (22050, 24000, 16000), 25: (11025, 12000, 8000)}
_MP3_SLACK_SECONDS = 0.5  # encoder delay, padding and the Xing frame are well under this


def _mpeg_frame(buf: bytes, pos: int) -> tuple[int, int, int, int] | None:
    """``(length_bytes, samples, sample_rate, version_layer_key)`` of the frame at ``pos``."""
    if pos + 4 > len(buf) or buf[pos] != 0xFF or buf[pos + 1] & 0xE0 != 0xE0:
        return None
    b1, b2 = buf[pos + 1], buf[pos + 2]
    version = {3: 1, 2: 2, 0: 25}.get((b1 >> 3) & 3)
    layer = {3: 1, 2: 2, 1: 3}.get((b1 >> 1) & 3)
    bitrate_index, rate_index, padding = b2 >> 4, (b2 >> 2) & 3, (b2 >> 1) & 1
    if version is None or layer is None or bitrate_index in (0, 15) or rate_index == 3:
        return None  # free-format bitrate (0) has no computable length: treat as no frame
    kbps = _MPEG_BITRATES[(1 if version == 1 else 2, layer)][bitrate_index]
    rate = _MPEG_RATES[version][rate_index]
    if layer == 1:
        length, samples = (12000 * kbps // rate + padding) * 4, 384
    elif layer == 2 or version == 1:
        length, samples = 144000 * kbps // rate + padding, 1152
    else:
        length, samples = 72000 * kbps // rate + padding, 576
    return length, samples, rate, version * 10 + layer


def _count_mpeg_samples(buf: bytes, stop_after: int) -> int:
    """Samples held by the chains of MPEG audio frames in ``buf``; stops past ``stop_after``.

    A chain starts at a frame whose next three frames parse with the same version, layer and
    rate (so stray ``0xFFE`` bit patterns in tags or junk do not count) and goes on while the
    frames keep parsing.
    """
    pos, total = 0, 0
    if buf[:3] == b"ID3" and len(buf) >= 10:
        size = (buf[6] & 0x7F) << 21 | (buf[7] & 0x7F) << 14 | (buf[8] & 0x7F) << 7 | buf[9] & 0x7F
        pos = 10 + size + (10 if buf[5] & 0x10 else 0)
    in_chain_key = None  # (rate, version-layer) of the chain being walked, if any
    while total <= stop_after:
        frame = _mpeg_frame(buf, pos)
        if frame is not None and (frame[2:] == in_chain_key or _chain_holds(buf, pos, frame, 3)):
            in_chain_key = frame[2:]
            total += frame[1]
            pos += frame[0]
            continue
        in_chain_key = None
        pos = buf.find(b"\xff", pos + 1)
        if pos < 0:
            break
    return total


def _chain_holds(buf: bytes, pos: int, frame: tuple[int, int, int, int], links: int) -> bool:
    for _ in range(links):
        pos += frame[0]
        if pos == len(buf):
            return True
        following = _mpeg_frame(buf, pos)
        if following is None or following[2:] != frame[2:]:
            return False
        frame = following
    return True


def _check_mp3_fully_decoded(file, decoded: int, sr: int) -> None:
    """Refuse an MP3 whose frames hold more audio than the decoder gave.

    libsndfile never reads past the length it computed at open, and for a VBR file without
    a Xing header (or two MP3 files concatenated) that length is an estimate that can be far
    too short: the rest of the song would silently go missing.
    """
    file.seek(0)
    buf = file.read()
    slack = int(_MP3_SLACK_SECONDS * sr)
    held = _count_mpeg_samples(buf, stop_after=decoded + slack)
    if held > decoded + slack:
        raise MotionError(
            f"the MP3 holds more audio than its header announces ({decoded / sr:.1f} s "
            "decoded): it may be two files joined or a VBR file without a Xing header; "
            "re-encode it",
            kind="unsupported",
        )


def check_not_silent(samples: np.ndarray, *, threshold_dbfs: float = SILENCE_DBFS) -> None:
    """Raise ``MotionError`` kind ``"unusable"`` when ``samples`` ``(N,)`` has no sound.

    Silence is a peak level below ``threshold_dbfs`` (-60 dBFS: 0.1 % of full scale). Callers
    of :func:`decode` that need music (dance) call this; features of silence are well defined
    (all at the floor, no beats) but useless.
    """
    samples = np.asarray(samples)
    if samples.size == 0:
        raise MotionError("the audio has no samples", kind="unusable")
    peak = float(np.max(np.abs(samples)))
    if not peak >= 10.0 ** (threshold_dbfs / 20.0):
        level = "-inf" if peak == 0 else f"{20 * math.log10(peak):.0f}"
        raise MotionError(
            f"the audio is silent: its peak level is {level} dBFS, below {threshold_dbfs:g} dBFS",
            kind="unusable",
        )


def resample(samples: np.ndarray, sr_in: int, sr_out: int) -> np.ndarray:
    """Resample ``(N,)`` or ``(N, C)`` audio from ``sr_in`` to ``sr_out`` Hz (soxr HQ).

    Returns float32 of length about ``N * sr_out / sr_in`` (a new array even when the rates
    are equal).
    """
    if not (sr_in > 0 and sr_out > 0):
        raise ValueError(f"sample rates must be positive, got {sr_in} and {sr_out}")
    samples = np.asarray(samples, dtype=np.float32)
    if sr_in == sr_out or len(samples) == 0:
        return samples.copy()
    return soxr.resample(samples, sr_in, sr_out, quality="HQ").astype(np.float32, copy=False)


# ---------------------------------------------------------------------------------------------
# Spectra


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
    windows = padded[centres[:, None] + np.arange(N_FFT)[None, :]] * _WINDOW
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


def _spectral_frames(samples: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    return _onset_from_log_mel(_onset_log_mel(_prepare_samples(samples, sr)), aggregate)


def _onset_log_mel(y: np.ndarray) -> np.ndarray:
    """Log-mel ``(T, ONSET_N_MELS)`` of ``y`` (FEATURE_SR) at hop ONSET_HOP, windows centred."""
    frames = 1 + len(y) // ONSET_HOP
    centres = np.arange(frames, dtype=np.int64) * ONSET_HOP
    padded = _pad_for_centres(y, int(centres[-1]))
    log_mel = np.empty((frames, ONSET_N_MELS), np.float32)
    for lo in range(0, frames, _CHUNK_FRAMES):
        power = _power_frames(padded, centres[lo : lo + _CHUNK_FRAMES])
        log_mel[lo : lo + len(power)] = _log_mel(power, _ONSET_MEL)
    return log_mel


def _onset_from_log_mel(log_mel: np.ndarray, aggregate) -> np.ndarray:
    frames = len(log_mel)
    rise = aggregate(np.maximum(0.0, log_mel[_ONSET_LAG:] - log_mel[:-_ONSET_LAG]), axis=1)
    envelope = np.concatenate([np.zeros(_ONSET_LAG + _ONSET_DELAY - 1), rise])
    return np.pad(envelope, (0, max(0, frames - len(envelope))))[:frames].astype(np.float32)


def estimate_tempo(
    onset: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    *,
    start_bpm: float = 120.0,
    std_octaves: float = 1.0,
    max_bpm: float = 320.0,
    window_seconds: float = 8.0,
) -> float:
    """Global tempo in bpm of an onset envelope ``(T,)`` sampled at ``frame_rate`` Hz.

    librosa's estimator: the autocorrelation of the envelope in Hann-windowed
    ``window_seconds`` frames (each normalised by its lag 0), averaged over time, weighted
    by a log-normal prior (``std_octaves`` wide around ``start_bpm``); the best lag is then
    refined to a fraction of a frame by fitting a parabola through it and its neighbours,
    which librosa does not do (at 43 Hz a whole-frame lag near 120 bpm is off by 2 %).
    Returns 0.0 when the envelope has no onsets.
    """
    onset = np.asarray(onset, dtype=np.float64)
    if onset.size == 0 or not onset.any():
        return 0.0
    mean_ac = _mean_local_autocorrelation(onset, int(window_seconds * frame_rate))
    lags = np.arange(len(mean_ac), dtype=np.float64)
    with np.errstate(divide="ignore"):
        bpms = 60.0 * frame_rate / lags
    log_prior = -0.5 * ((np.log2(bpms[1:]) - np.log2(start_bpm)) / std_octaves) ** 2
    log_prior = np.concatenate([[-np.inf], np.where(bpms[1:] < max_bpm, log_prior, -np.inf)])
    score = np.log1p(1e6 * mean_ac) + log_prior
    best = int(np.argmax(score))
    lag = float(best)
    if 1 <= best - 1 and best + 1 < len(score) and np.isfinite(score[best - 1]):
        left, mid, right = score[best - 1], score[best], score[best + 1]
        curvature = left - 2.0 * mid + right
        if curvature < 0:
            lag += 0.5 * (left - right) / curvature
    return float(60.0 * frame_rate / lag)


def _mean_local_autocorrelation(onset: np.ndarray, window: int) -> np.ndarray:
    """Mean over frames of the normalised autocorrelation ``(window,)`` of Hann-windowed
    excerpts centred on each frame (librosa's ``tempogram`` averaged over time)."""
    window = max(4, min(window, 2 * len(onset)))
    half = window // 2
    ramp_in = np.linspace(0.0, onset[0], half, endpoint=False)
    ramp_out = np.linspace(onset[-1], 0.0, window - half + 1)[1:]  # librosa: linear ramps
    padded = np.concatenate([ramp_in, onset, ramp_out])
    taper = np.hanning(window + 1)[:-1]
    n_fft = scipy.fft.next_fast_len(2 * window - 1)
    total = np.zeros(window)
    for lo in range(0, len(onset), _CHUNK_FRAMES):
        starts = np.arange(lo, min(lo + _CHUNK_FRAMES, len(onset)))
        excerpts = padded[starts[:, None] + np.arange(window)[None, :]] * taper
        spectrum = scipy.fft.rfft(excerpts, n=n_fft, axis=1)
        ac = scipy.fft.irfft(spectrum.real**2 + spectrum.imag**2, n=n_fft, axis=1)[:, :window]
        peak = np.abs(ac).max(axis=1, keepdims=True)
        total += (ac / np.where(peak > 1e-30, peak, 1.0)).sum(axis=0)
    return total / len(onset)


def track_beats(
    onset: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    *,
    bpm: float | None = None,
    tightness: float = 100.0,
) -> tuple[float, np.ndarray]:
    """Tempo (bpm) and beat times ``(B,)`` in seconds from an onset envelope ``(T,)``.

    Ellis (2007) dynamic programming, as in ``librosa.beat.beat_track``: beat ``i``'s score
    is the onset strength there (smoothed by a Gaussian of a 32nd of a beat) plus the best
    score of a previous beat ``d`` frames back, penalised by ``tightness * log(d / period)^2``;
    the path is traced back from the last strong beat and weak beats at either end are
    dropped. ``bpm`` defaults to :func:`estimate_tempo`. Returns ``(0.0, [])`` when there
    are no onsets. Frame ``t`` of the envelope is time ``t / frame_rate``.
    """
    onset = np.asarray(onset, dtype=np.float64)
    if onset.ndim != 1:
        raise ValueError(f"onset must be 1-D (T,), got shape {onset.shape}")
    if onset.size < 2 or not onset.any():
        return 0.0, np.zeros(0)
    tempo = estimate_tempo(onset, frame_rate) if bpm is None else float(bpm)
    if not tempo > 0:
        raise ValueError(f"bpm must be positive, got {bpm}")
    period = frame_rate * 60.0 / tempo
    local = _local_score(onset / (onset.std(ddof=1) + 1e-30), period)
    backlink, cumulative = _beat_dp(local, period, tightness)
    beats = _backtrack(backlink, _last_beat(cumulative))
    beats = _trim_weak_ends(local, beats)
    return tempo, beats / frame_rate


def _local_score(onset: np.ndarray, period: float) -> np.ndarray:
    reach = round(period)
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) * 32.0 / period) ** 2)
    return np.convolve(onset, kernel, mode="same")


def _beat_dp(local: np.ndarray, period: float, tightness: float) -> tuple[np.ndarray, np.ndarray]:
    """Backlinks ``(T,)`` (-1: first beat) and cumulative scores ``(T,)``."""
    nearest, farthest = max(1, round(period / 2.0)), round(2.0 * period)
    gaps = np.arange(nearest, farthest + 1)  # candidate distances to the previous beat
    penalty = tightness * (np.log(gaps) - np.log(period)) ** 2
    count = len(local)
    cumulative = np.empty(count)
    backlink = np.full(count, -1, dtype=np.int64)
    threshold = 0.01 * local.max()
    started = False
    for i in range(count):
        usable = gaps[gaps <= i]  # previous beats must lie at or after frame 0
        best_prev = -1
        best = 0.0
        if usable.size:
            scores = cumulative[i - usable] - penalty[: usable.size]
            k = int(np.argmax(scores))  # first maximum = nearest predecessor, as librosa
            best_prev, best = i - int(usable[k]), float(scores[k])
        cumulative[i] = local[i] + best if best_prev >= 0 else local[i]
        if started or local[i] >= threshold:
            backlink[i] = best_prev
            started = True
    return backlink, cumulative


def _last_beat(cumulative: np.ndarray) -> int:
    """Last local maximum of the cumulative score that reaches half their median."""
    left = np.concatenate([[cumulative[0]], cumulative[:-1]])
    right = np.concatenate([cumulative[1:], [cumulative[-1]]])
    peaks = np.flatnonzero((cumulative > left) & (cumulative >= right))
    if peaks.size == 0:
        return len(cumulative) - 1
    threshold = 0.5 * np.median(cumulative[peaks])
    strong = peaks[cumulative[peaks] >= threshold]
    return int(strong[-1]) if strong.size else len(cumulative) - 1


def _backtrack(backlink: np.ndarray, tail: int) -> np.ndarray:
    beats = []
    frame = tail
    while frame >= 0:
        beats.append(frame)
        frame = int(backlink[frame])
    return np.array(beats[::-1], dtype=np.int64)


def _trim_weak_ends(local: np.ndarray, beats: np.ndarray) -> np.ndarray:
    """Drop beats before the first / after the last frame whose local score exceeds half the
    RMS of the beats' smoothed local scores (librosa's ``trim=True``)."""
    if beats.size == 0:
        return beats
    # librosa's RMS runs over the full convolution less its first two values (B + 2 values)
    smooth = np.convolve(local[beats], np.hanning(5))[2:]
    threshold = 0.5 * np.sqrt(np.mean(smooth**2))
    strong = np.flatnonzero(local > threshold)
    if strong.size == 0:
        return beats[:0]
    return beats[(beats >= strong[0]) & (beats <= strong[-1])]


def beat_phase(
    beat_times: np.ndarray, num_frames: int, fps: float, *, period: float | None = None
) -> np.ndarray:
    """Phase in ``[0, 1)`` of each motion frame ``(num_frames,)`` within its beat.

    0 at each beat, rising linearly to the next. Before the first and after the last beat
    the beat grid is extrapolated with ``period`` seconds (default: the median interval of
    ``beat_times`` ``(B,)``). With no beats, or one beat and no period, every phase is 0.
    Frame ``i`` is time ``i / fps``.
    """
    beat_times = np.sort(np.asarray(beat_times, dtype=np.float64))
    times = np.arange(num_frames, dtype=np.float64) / fps
    if period is None and beat_times.size >= 2:
        period = float(np.median(np.diff(beat_times)))
    if beat_times.size == 0 or period is None or not period > 0:
        return np.zeros(num_frames, dtype=np.float32)
    phase = np.empty(num_frames, dtype=np.float64)
    before = times < beat_times[0]
    after = times >= beat_times[-1]
    inside = ~before & ~after
    phase[before] = (times[before] - beat_times[0]) / period
    phase[after] = (times[after] - beat_times[-1]) / period
    k = np.searchsorted(beat_times, times[inside], side="right") - 1
    phase[inside] = (times[inside] - beat_times[k]) / (beat_times[k + 1] - beat_times[k])
    phase = np.mod(phase, 1.0)
    phase[phase >= 1.0] = 0.0  # mod of a tiny negative number rounds to 1.0: on the beat
    # just below the next beat float32 can round up to 1.0: keep the largest value below
    return np.minimum(phase.astype(np.float32), np.float32(1.0) - np.finfo(np.float32).epsneg)


# ---------------------------------------------------------------------------------------------
# Per-motion-frame features


@dataclass(frozen=True, eq=False)
class AudioFeatures:
    """Audio features with one row per motion frame (``F`` frames at ``fps``).

    ``mel`` ``(F, N_MELS)`` log-mel power in dB (0 dB: a full-scale sine's STFT bin; the
    Slaney-normalised bands then sit lower, about -18 dB for a full-scale 1 kHz sine; floor
    DB_FLOOR); ``spectral``
    ``(F, len(SPECTRAL_COLUMNS))``; ``onset`` ``(F,)`` onset strength (the largest value of
    the fine envelope within half a frame of the frame's instant); ``beat_phase`` ``(F,)`` in
    ``[0, 1)``; ``beats`` ``(B,)`` beat times in seconds; ``tempo`` in bpm (0 when no beat was
    found). Values are in the units stated, not normalised: networks normalise them with
    statistics saved at training time.
    """

    fps: float
    mel: np.ndarray
    spectral: np.ndarray
    onset: np.ndarray
    beat_phase: np.ndarray
    beats: np.ndarray
    tempo: float

    @property
    def num_frames(self) -> int:
        return len(self.onset)

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
    y = _prepare_samples(samples, sr)
    if num_frames is None:
        num_frames = math.ceil(len(np.asarray(samples)) / sr * fps - 1e-9)
    if num_frames < 0:
        raise ValueError(f"num_frames must be >= 0, got {num_frames}")
    centres = np.round(np.arange(num_frames) * (FEATURE_SR / fps)).astype(np.int64)
    mel, spectral = _spectral_frames(y, centres)
    log_mel = _onset_log_mel(y)
    envelope = _onset_from_log_mel(log_mel, np.mean)
    tempo, beats = track_beats(_onset_from_log_mel(log_mel, np.median), ONSET_FRAME_RATE)
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
    )


def _prepare_samples(samples: np.ndarray, sr: int) -> np.ndarray:
    """Validate mono ``(N,)`` audio and resample it to FEATURE_SR (float32)."""
    samples = np.asarray(samples)
    if samples.ndim != 1:
        raise ValueError(f"samples must be mono (N,), got shape {samples.shape}")
    if samples.size == 0:
        raise MotionError("the audio has no samples", kind="unusable")
    _check_sample_values(samples)
    if not (isinstance(sr, int | np.integer) and sr > 0):
        raise ValueError(f"sr must be a positive integer, got {sr!r}")
    return resample(samples, int(sr), FEATURE_SR)


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

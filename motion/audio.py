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
    return _onset_from_log_mel(_db(_onset_mel(_prepare_samples(samples, sr))), aggregate)


def _onset_mel(y: np.ndarray) -> np.ndarray:
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


def _db(mel: np.ndarray) -> np.ndarray:
    db = 10.0 * np.log10(np.maximum(mel, 10.0 ** (DB_FLOOR / 10.0)))
    return np.maximum(db, DB_FLOOR)


def _onset_from_log_mel(log_mel: np.ndarray, aggregate) -> np.ndarray:
    return _rise_envelope(log_mel, lambda rise: aggregate(rise, axis=1))


def _rise_envelope(levels: np.ndarray, combine) -> np.ndarray:
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
_ONSET_MEL_HZ = (_ONSET_MEL @ _FFT_HZ) / _ONSET_MEL.sum(axis=1)
_BEAT_BAND_WEIGHTS = np.where(
    _ONSET_MEL_HZ < BEAT_LOW_HZ,
    BEAT_LOW_SHARE / np.count_nonzero(_ONSET_MEL_HZ < BEAT_LOW_HZ),
    (1.0 - BEAT_LOW_SHARE) / np.count_nonzero(_ONSET_MEL_HZ >= BEAT_LOW_HZ),
).astype(np.float32)


def beat_onset_strength(samples: np.ndarray, sr: int) -> np.ndarray:
    """The envelope ``(T,)`` :func:`frame_features` tracks beats on (ONSET_FRAME_RATE, timed
    as :func:`onset_strength`): the rise of compressed mel magnitudes (see
    :data:`BEAT_COMPRESSION`), weighted so that the bands below :data:`BEAT_LOW_HZ` count as
    much as :data:`BEAT_LOW_SHARE` of the whole. Kick and bass, which few bands hold, then
    set the beat, not hi-hats, whose bright rise fills most bands: on a kick every beat with
    a hi-hat halfway between, the median rise of dB over bands (librosa's) puts every beat
    on the hi-hats."""
    return _beat_envelope(_onset_mel(_prepare_samples(samples, sr)))


def _beat_levels(mel: np.ndarray) -> np.ndarray:
    """``log(1 + BEAT_COMPRESSION * magnitude / loudest)`` of mel power ``(T, bands)``."""
    magnitude = np.sqrt(mel)
    scale = float(np.percentile(magnitude, 99.9)) if magnitude.size else 0.0
    return np.log1p((BEAT_COMPRESSION / max(scale, 1e-12)) * magnitude)


def _beat_envelope(mel: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    levels = _beat_levels(mel) if levels is None else levels
    return _rise_envelope(levels, lambda rise: rise @ _BEAT_BAND_WEIGHTS)


MAX_BPM = 200.0
"""Fastest beat :func:`estimate_tempo` reports: listeners tap beats up to about here."""
LOCAL_TEMPO_SECONDS = 12.0
"""Span of the autocorrelation that sets the local tempo the beat tracker follows."""
LOCAL_TEMPO_RANGE = 1.35
"""The local tempo stays within this factor of the song's tempo (its octave)."""
_ACF_STRIDE = 2  # autocorrelations of every other frame's excerpt: 8-s windows overlap anyway


@dataclass(frozen=True)
class Tempo:
    """The tempo of an onset envelope: ``bpm`` for the whole song and ``period (T,)``, the
    local beat period in envelope frames at every frame."""

    bpm: float
    period: np.ndarray


def estimate_tempo(
    onset: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    *,
    start_bpm: float = 120.0,
    std_octaves: float = 1.0,
    max_bpm: float = MAX_BPM,
    window_seconds: float = 8.0,
) -> float:
    """Global tempo in bpm of an onset envelope ``(T,)`` sampled at ``frame_rate`` Hz
    (:func:`tempo_curve`'s ``bpm``); 0.0 when the envelope has no onsets."""
    return tempo_curve(
        onset, frame_rate, start_bpm=start_bpm, std_octaves=std_octaves, max_bpm=max_bpm,
        window_seconds=window_seconds,
    ).bpm  # fmt: skip


def tempo_curve(
    onset: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    *,
    start_bpm: float = 120.0,
    std_octaves: float = 1.0,
    max_bpm: float = MAX_BPM,
    window_seconds: float = 8.0,
) -> Tempo:
    """Global and local tempo of an onset envelope ``(T,)`` sampled at ``frame_rate`` Hz.

    Global: librosa's estimator, the autocorrelation of the envelope in Hann-windowed
    ``window_seconds`` frames (each normalised by its lag 0), averaged over time, weighted
    by a log-normal prior (``std_octaves`` wide around ``start_bpm``), refined to a fraction
    of a frame by a parabola (at 43 Hz a whole-frame lag near 120 bpm is off by 2 %). The
    prior picks the octave where the envelope is as periodic at twice the lag as at the lag:
    songs at 180 bpm come out at 90 (a rule that doubled a tempo whenever half the lag was
    as periodic got them right, but also doubled 8 of the 23 Dance with Melody songs, whose
    eighth notes are as regular as their beats). Local: the same autocorrelation averaged over
    :data:`LOCAL_TEMPO_SECONDS` around each second, its best lag within
    :data:`LOCAL_TEMPO_RANGE` of the global one, median-filtered over 5 s, so a tempo change
    is followed without leaving the octave. ``bpm`` is 0.0 (and ``period`` empty) when the
    envelope has no onsets.
    """
    onset = np.asarray(onset, dtype=np.float64)
    if onset.size == 0 or not onset.any():
        return Tempo(0.0, np.zeros(0))
    block = max(_ACF_STRIDE, _ACF_STRIDE * int(round(frame_rate / _ACF_STRIDE)))  # ~1 s
    sums = _block_autocorrelation(onset, int(window_seconds * frame_rate), block)
    mean_ac = sums.sum(axis=0) / len(onset)
    lags = np.arange(len(mean_ac), dtype=np.float64)
    with np.errstate(divide="ignore"):
        bpms = 60.0 * frame_rate / lags
    log_prior = -0.5 * ((np.log2(bpms[1:]) - np.log2(start_bpm)) / std_octaves) ** 2
    log_prior = np.concatenate([[-np.inf], np.where(bpms[1:] < max_bpm, log_prior, -np.inf)])
    lag = _refined_peak(np.log1p(1e6 * mean_ac) + log_prior, int(np.argmax(log_prior)))
    period = _local_periods(sums, lag, block, len(onset), frame_rate)
    return Tempo(float(60.0 * frame_rate / lag), period)


def _refined_peak(score: np.ndarray, fallback: int) -> float:
    """Argmax of ``score`` refined by a parabola through it and its neighbours."""
    if not np.isfinite(score).any():
        return float(fallback)
    best = int(np.argmax(score))
    lag = float(best)
    if 1 <= best - 1 and best + 1 < len(score) and np.isfinite(score[best - 1]):
        left, mid, right = score[best - 1], score[best], score[best + 1]
        curvature = left - 2.0 * mid + right
        if curvature < 0 and np.isfinite(right):
            lag += 0.5 * (left - right) / curvature
    return lag


def _local_periods(sums: np.ndarray, lag: float, block: int, frames: int, frame_rate: float):
    """``(frames,)`` local beat period (frames) within LOCAL_TEMPO_RANGE of ``lag``."""
    from scipy.ndimage import median_filter, uniform_filter1d

    span = max(1, int(round(LOCAL_TEMPO_SECONDS * frame_rate / block)))
    local = uniform_filter1d(sums, span, axis=0, mode="nearest")
    lo = max(1, int(np.floor(lag / LOCAL_TEMPO_RANGE)))
    hi = min(sums.shape[1] - 2, int(np.ceil(lag * LOCAL_TEMPO_RANGE)))
    if hi <= lo:
        return np.full(frames, lag)
    best = np.array([lo + _refined_peak(row[lo : hi + 1], 0) for row in local])
    best = median_filter(best, size=min(5, len(best)), mode="nearest")
    centres = (np.arange(len(best)) + 0.5) * block
    return np.interp(np.arange(frames), centres, best)


def _block_autocorrelation(onset: np.ndarray, window: int, block: int) -> np.ndarray:
    """Sums over each run of ``block`` frames ``(ceil(T / block), window)`` of the
    normalised autocorrelation of Hann-windowed excerpts centred on each frame (librosa's
    ``tempogram``)."""
    window = max(4, min(window, 2 * len(onset)))
    half = window // 2
    ramp_in = np.linspace(0.0, onset[0], half, endpoint=False)
    ramp_out = np.linspace(onset[-1], 0.0, window - half + 1)[1:]  # librosa: linear ramps
    padded = np.concatenate([ramp_in, onset, ramp_out])
    taper = np.hanning(window + 1)[:-1]
    n_fft = scipy.fft.next_fast_len(2 * window - 1)
    chunk = max(block, _CHUNK_FRAMES // block * block)
    out = np.zeros((-(-len(onset) // block), window))
    stride = _ACF_STRIDE if block % _ACF_STRIDE == 0 else 1
    for lo in range(0, len(onset), chunk):
        starts = np.arange(lo, min(lo + chunk, len(onset)), stride)
        excerpts = padded[starts[:, None] + np.arange(window)[None, :]] * taper
        spectrum = scipy.fft.rfft(excerpts, n=n_fft, axis=1)
        ac = scipy.fft.irfft(spectrum.real**2 + spectrum.imag**2, n=n_fft, axis=1)[:, :window]
        peak = np.abs(ac).max(axis=1, keepdims=True)
        ac /= np.where(peak > 1e-30, peak, 1.0)
        out[lo // block : lo // block + -(-len(starts) * stride // block)] += stride * (
            np.add.reduceat(ac, np.arange(0, len(starts), block // stride), axis=0)
        )
    return out


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
    score of a previous beat ``d`` frames back, penalised by ``tightness * log(d / p)^2``;
    the path is traced back from the last strong beat and weak beats at either end are
    dropped. ``p`` is the local period of :func:`tempo_curve` (so a tempo change is
    followed), or constant when ``bpm`` is given (then this is librosa's tracker). Returns
    ``(0.0, [])`` when there are no onsets. Frame ``t`` of the envelope is time
    ``t / frame_rate``.
    """
    onset = np.asarray(onset, dtype=np.float64)
    if onset.ndim != 1:
        raise ValueError(f"onset must be 1-D (T,), got shape {onset.shape}")
    if onset.size < 2 or not onset.any():
        return 0.0, np.zeros(0)
    if bpm is None:
        estimate = tempo_curve(onset, frame_rate)
        tempo, periods = estimate.bpm, estimate.period
    else:
        tempo = float(bpm)
        if not tempo > 0:
            raise ValueError(f"bpm must be positive, got {bpm}")
        periods = np.full(len(onset), frame_rate * 60.0 / tempo)
    period = frame_rate * 60.0 / tempo
    local = _local_score(onset / (onset.std(ddof=1) + 1e-30), period)
    backlink, cumulative = _beat_dp(local, periods, tightness)
    beats = _backtrack(backlink, _last_beat(cumulative))
    beats = _trim_weak_ends(local, beats)
    return tempo, beats / frame_rate


def _local_score(onset: np.ndarray, period: float) -> np.ndarray:
    reach = round(period)
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) * 32.0 / period) ** 2)
    return np.convolve(onset, kernel, mode="same")


def _beat_dp(
    local: np.ndarray, periods: np.ndarray, tightness: float
) -> tuple[np.ndarray, np.ndarray]:
    """Backlinks ``(T,)`` (-1: first beat) and cumulative scores ``(T,)``; ``periods (T,)``
    the beat period (frames) expected before each frame."""
    nearest, farthest = max(1, round(periods.min() / 2.0)), round(2.0 * periods.max())
    gaps = np.arange(nearest, farthest + 1)  # candidate distances to the previous beat
    # penalties per distinct period (a local tempo takes few values: rounded to 0.1 %)
    keys = np.round(np.log(periods) * 1000.0).astype(np.int64)
    distinct, which = np.unique(keys, return_inverse=True)
    penalties = tightness * (np.log(gaps)[None, :] - distinct[:, None] / 1000.0) ** 2
    count = len(local)
    cumulative = np.empty(count)
    backlink = np.full(count, -1, dtype=np.int64)
    threshold = 0.01 * local.max()
    started = False
    for i in range(count):
        usable = gaps if i >= gaps[-1] else gaps[gaps <= i]  # beats at or after frame 0
        best_prev = -1
        best = 0.0
        if usable.size:
            scores = cumulative[i - usable] - penalties[which[i], : usable.size]
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


BAR_LENGTHS = (4, 3)
"""Beats per bar :func:`downbeats` considers; 3 must win by :data:`TRIPLE_MARGIN`."""
TRIPLE_MARGIN = 1.25


def downbeats(
    beats: np.ndarray,
    mel: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    levels: np.ndarray | None = None,
):
    """Downbeat times ``(D,)`` (a subset of ``beats (B,)``, seconds) and beats per bar.

    Each beat gets an accent: the rise of the low bands (kick, bass) within 50 ms of it,
    plus how much the spectrum of the beat after it differs from the beat before (chords
    change at bar lines), each standardised over the song. The bar length (4, or 3 if its
    best phase scores :data:`TRIPLE_MARGIN` times 4's) and phase are those whose beats are
    most accented above the others. ``mel (T, ONSET_N_MELS)``: the onset mel power
    (``levels``: its compressed magnitudes, when already computed).
    Fewer than two bars of beats: no downbeats.
    """
    beats = np.asarray(beats, dtype=np.float64)
    if beats.size < 2 * max(BAR_LENGTHS) or len(mel) == 0:
        return beats[:0], 0
    frames = np.clip(np.round(beats * frame_rate).astype(np.int64), 0, len(mel) - 1)
    levels = _beat_levels(mel) if levels is None else levels
    low = _ONSET_MEL_HZ < BEAT_LOW_HZ
    low_rise = _rise_envelope(levels[:, low], lambda rise: rise.mean(axis=1))
    reach = max(1, int(round(0.05 * frame_rate)))
    kick = np.array([low_rise[max(0, f - reach) : f + reach + 1].max() for f in frames])
    edges = np.concatenate([[max(0, 2 * frames[0] - frames[1])], frames, [len(mel)]])
    spans = [levels[a:b].mean(axis=0) if b > a else levels[min(a, len(mel) - 1)]
             for a, b in zip(edges[:-1], edges[1:], strict=True)]  # fmt: skip
    spectra = np.stack(spans)  # (B + 1, bands): before beat 0, then after each beat
    change = np.linalg.norm(spectra[1:] - spectra[:-1], axis=1)

    def standard(x):
        return (x - x.mean()) / (x.std() + 1e-9)

    accent = standard(kick) + standard(change)
    best = {}
    for bar in BAR_LENGTHS:
        scores = [accent[p::bar].mean() - np.delete(accent, np.s_[p::bar]).mean()
                  for p in range(bar)]  # fmt: skip
        best[bar] = (max(scores), int(np.argmax(scores)))
    bar = 3 if best[3][0] > TRIPLE_MARGIN * max(best[4][0], 1e-9) else 4
    return beats[best[bar][1] :: bar], bar


HALF_BEAT_SHARE = 0.45
""":func:`pulses` counts the half-beats too when their onsets are this strong next to the
beats' (the beat envelope's peak within 50 ms, averaged over the song)."""


def pulses(beats: np.ndarray, envelope: np.ndarray, frame_rate: float = ONSET_FRAME_RATE):
    """The music's strong pulses ``(P,)`` (seconds): ``beats (B,)``, and the points halfway
    between them when the song accents those nearly as much (:data:`HALF_BEAT_SHARE`) and
    the doubled tempo stays under :data:`MAX_BPM`. A song at 180 bpm whose kick and snare
    alternate on every beat is tracked at 90 (the prior's octave, which 90-bpm rumbas with
    strong eighths need too): its dance should still land on every hit."""
    beats = np.asarray(beats, dtype=np.float64)
    envelope = np.asarray(envelope, dtype=np.float64)
    if beats.size < 2 or envelope.size == 0:
        return beats
    if 2 * 60.0 / float(np.median(np.diff(beats))) > MAX_BPM:
        return beats
    mids = 0.5 * (beats[:-1] + beats[1:])
    reach = max(1, int(round(0.05 * frame_rate)))

    def peaks(times):
        frames = np.clip(np.round(times * frame_rate).astype(np.int64), 0, len(envelope) - 1)
        return np.array([envelope[max(0, f - reach) : f + reach + 1].max() for f in frames])

    if peaks(mids).mean() < HALF_BEAT_SHARE * max(peaks(beats).mean(), 1e-12):
        return beats
    return np.sort(np.concatenate([beats, mids]))


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
    ``[0, 1)``; ``beats`` ``(B,)`` beat times in seconds (:func:`beat_onset_strength`,
    :func:`track_beats`); ``tempo`` in bpm (0 when no beat was found); ``downbeats``
    ``(D,)`` the beats that start a bar of ``beats_per_bar`` (:func:`downbeats`; empty and 0
    when the song has under two bars); ``pulses`` ``(P,)`` the beats and, where the song
    accents them as much, the half-beats (:func:`pulses`: what a dance should land on).
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

    @property
    def num_frames(self) -> int:
        return len(self.onset)

    @property
    def playing(self) -> np.ndarray:
        """``(F,)`` bool: the music sounds at the frame (RMS above :data:`SILENCE_DBFS`)."""
        return self.spectral[:, SPECTRAL_COLUMNS.index("rms_db")] > SILENCE_DBFS

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
    onset_mel = _onset_mel(y)
    envelope = _onset_from_log_mel(_db(onset_mel), np.mean)
    levels = _beat_levels(onset_mel)
    beat_envelope = _beat_envelope(onset_mel, levels)
    tempo, beats = track_beats(beat_envelope, ONSET_FRAME_RATE)
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
        pulses=pulses(beats, beat_envelope),
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


def beat_f_measure(estimated: np.ndarray, reference: np.ndarray, window: float = 0.07) -> float:
    """F-measure of ``estimated (E,)`` beat times against ``reference (R,)`` (seconds), as
    ``mir_eval.beat.f_measure``: an estimated beat is a hit when it lies within ``window``
    seconds of a reference beat not matched already (each beat matches at most once; with
    beats further apart than twice the window, nearest-first matching is a maximum one).
    0.0 when either side is empty."""
    est = np.sort(np.asarray(estimated, dtype=np.float64))
    ref = np.sort(np.asarray(reference, dtype=np.float64))
    if est.size == 0 or ref.size == 0:
        return 0.0
    distance = np.abs(est[:, None] - ref[None, :])
    pairs = np.argwhere(distance <= window)
    order = np.argsort(distance[pairs[:, 0], pairs[:, 1]], kind="stable")
    used_est, used_ref = set(), set()
    for e, r in pairs[order]:
        if e not in used_est and r not in used_ref:
            used_est.add(int(e))
            used_ref.add(int(r))
    hits = len(used_est)
    if hits == 0:
        return 0.0
    precision, recall = hits / est.size, hits / ref.size
    return 2.0 * precision * recall / (precision + recall)

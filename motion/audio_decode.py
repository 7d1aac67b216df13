"""Audio files to samples: any wav/flac/ogg/mp3 decoded to mono float32, checked for sound,
resampled.

:func:`decode` reads in blocks and stops as soon as the audio runs past a limit, so an
over-long upload is never decoded in full; an MP3 whose frames hold more audio than its
header announces is refused rather than cut short (:func:`_check_mp3_fully_decoded`).
"""

from __future__ import annotations

import io
import math
import os

import numpy as np
import soundfile
import soxr

from motion.errors import MotionError

ALLOWED_CONTAINERS = ("WAV", "WAVEX", "RF64", "W64", "AIFF", "FLAC", "OGG", "MP3")
"""libsndfile container names :func:`decode` accepts; others it recognises are refused."""
MIN_SAMPLE_RATE, MAX_SAMPLE_RATE = 4000, 384000
MAX_CHANNELS = 32
MAX_ABS_SAMPLE = 1000.0
"""Float samples beyond this (60 dB over full scale) are damage, not headroom."""
SILENCE_DBFS = -60.0
""":func:`check_not_silent` refuses audio whose peak is below this level."""

_READ_BLOCK = 1 << 16  # frames per read: bounds memory and lets max_seconds stop early
_SF_ERR_UNSUPPORTED_ENCODING = 4  # libsndfile's public code for a known container, unknown codec


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


def check_sample_values(samples: np.ndarray) -> None:
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
        check_sample_values(mono)
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

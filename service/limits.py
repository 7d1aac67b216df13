"""Request limits that engines enforce: frames per clip and seconds of audio (413 problems).

The upload size is enforced for every request by :class:`service.middleware.UploadLimitMiddleware`
and the time of one inference by :class:`service.inference.InferenceRunner`; these helpers
cover what only an engine can see once it has read a file::

    limits.check_frames(motion, settings, what="content")      # input and output frames
    limits.check_frames(result, settings, what="result")
    samples, sr = limits.decode_audio(raw, settings)            # stops decoding at the limit
    kp = limits.read_keypoints(raw, settings)

Every refusal is :class:`~service.errors.PayloadTooLarge`: a 413 problem whose ``limit`` is
the number, ``limit_name`` the setting (``max_frames``, ``max_audio_seconds``, as in
``MOTION_MAX_FRAMES``), and ``detail`` says both and the value found.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from motion.errors import MotionError
from service.config import Settings
from service.errors import PayloadTooLarge

if TYPE_CHECKING:
    import numpy as np

    from motion.keypoints import Keypoints2D


class HasFrames(Protocol):
    @property
    def num_frames(self) -> int: ...


def frames_over_limit(frames: int, settings: Settings, *, what: str = "clip") -> PayloadTooLarge:
    return PayloadTooLarge(
        f"the {what} has {frames} frames, over the limit of {settings.max_frames} (max_frames)",
        limit=settings.max_frames,
        limit_name="max_frames",
        frames=frames,
    )


def check_frames(clip: HasFrames | int, settings: Settings, *, what: str = "clip") -> int:
    """Raise a 413 problem when ``clip`` (a Motion, Keypoints2D or a frame count) has more
    than ``settings.max_frames`` frames; return the count. ``what`` names it in the detail
    (``"content"``, ``"style"``, ``"result"``)."""
    frames = clip if isinstance(clip, int) else int(clip.num_frames)
    if frames > settings.max_frames:
        raise frames_over_limit(frames, settings, what=what)
    return frames


def audio_over_limit(seconds: float | None, settings: Settings) -> PayloadTooLarge:
    limit = settings.max_audio_seconds
    found = f"{seconds:.1f} s long, " if seconds is not None else "longer than the limit, "
    return PayloadTooLarge(
        f"the audio is {found}over the limit of {limit:g} s (max_audio_seconds)",
        limit=limit,
        limit_name="max_audio_seconds",
    )


def check_audio_seconds(
    seconds: float | np.ndarray, settings: Settings, sample_rate: int | None = None
) -> float:
    """Raise a 413 problem when the audio lasts more than ``settings.max_audio_seconds``.

    ``seconds`` is a duration, or the samples ``(N,)`` (or ``(N, C)``) with ``sample_rate``.
    Returns the duration in seconds.
    """
    if sample_rate is not None:
        if sample_rate <= 0:
            raise ValueError(f"sample_rate must be positive, got {sample_rate}")
        duration = len(seconds) / float(sample_rate)  # type: ignore[arg-type]
    else:
        duration = float(seconds)  # type: ignore[arg-type]
    if duration > settings.max_audio_seconds:
        raise audio_over_limit(duration, settings)
    return duration


def decode_audio(data: bytes, settings: Settings) -> tuple[np.ndarray, int]:
    """Decode uploaded audio (:func:`motion.audio_decode.decode`), never past the audio limit:
    decoding stops as soon as it passes ``max_audio_seconds`` and a 413 problem names it."""
    from motion import audio_decode

    try:
        return audio_decode.decode(data, max_seconds=settings.max_audio_seconds)
    except MotionError as exc:
        if exc.kind == "too-large":
            raise audio_over_limit(None, settings) from None
        raise


def read_keypoints(data: bytes | str, settings: Settings, **options) -> Keypoints2D:
    """Load uploaded 2D keypoints (:func:`motion.keypoints.load`) within ``max_frames`` frames
    and ``max_upload_bytes`` bytes (unpacked, for a zip); ``options`` go to ``load``."""
    from motion import keypoints

    try:
        return keypoints.load(
            data,
            max_frames=settings.max_frames,
            max_bytes=settings.max_upload_bytes,
            **options,
        )
    except MotionError as exc:
        if exc.kind != "too-large":
            raise
        name = "max_upload_bytes" if "bytes" in exc.message else "max_frames"
        raise PayloadTooLarge(f"{exc.message} ({name})", limit=exc.limit, limit_name=name) from None

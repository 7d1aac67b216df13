"""The dance network's encodings (jacob2019, made to work), shared by training and serving.

Per motion frame at 30 fps (canonical skeleton), numpy only, so PyTorch training and the
onnxruntime service compute the same numbers.

Audio input ``(F, AUDIO_CHANNELS)``: ``motion.audio_features.AudioFeatures.matrix()``
(log-mel 64, the thesis's spectral summary 30: MFCCs, chroma, centroid, bandwidth, rolloff,
flatness, RMS; onset strength; beat phase as sin/cos). Beat sin/cos are left unstandardised, and
both 0 means "beat unknown" (music whose pairing with its dance was not verified; motion
without music). :func:`song_features` computes them for a song excerpt with the beat grid
of the whole song.

Genre: an index into :data:`GENRES` (the four music genres of Dance with Melody, then the
CMU dances that have no music), given to the network as a one-hot (or probability) vector.

Motion ``(F, MOTION_CHANNELS)``, in this channel order:

- ``ROTATION_CHANNELS`` (126): the 21 body joints' rotations as 6D (two matrix columns):
  Hips relative to the facing frame (so the hips never carry the heading: the thesis's
  180-degree hip flips cannot be expressed), the others local;
- ``ROOT_CHANNELS`` (4): Hips height, root velocity on the floor in the facing frame
  (sideways, forward), all in leg lengths (per second), and turning velocity (rad/s);
- ``CONTACT_CHANNELS`` (4): foot contacts of Foot_L, Toes_L, Foot_R, Toes_R as 0/1.

:func:`decode` inverts :func:`encode` (integrating the root velocity and turning from a
start point and heading). :class:`DanceStats` standardises both sides (``.npz`` beside the
model). Arrays are ``(F, C)`` float32, frames first.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt  # at import: its first import took 0.9 s of a request

from motion import audio_features, beat_tracking
from motion import beat_warp as BW
from motion import canonical as C
from motion import contacts as CT
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion

FPS = C.FPS
LEG = C.leg_length()
HIPS = C.INDEX["Hips"]
BODY = np.arange(1, len(C.JOINTS))  # every joint but joint_Root (which never moves)
FACING_JOINTS = tuple(C.INDEX[n] for n in ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R"))
FACING_SMOOTH = 2.0  # Gaussian sigma in frames
FOOT_JOINTS = list(CT.CANONICAL_FOOT_JOINTS)  # Foot_L, Toes_L, Foot_R, Toes_R

GENRES = ("cha-cha", "rumba", "tango", "waltz", "salsa", "indian", "modern")
MUSIC_GENRES = GENRES[:4]
"""Genres with music in the training data: the ones the audio classifier head predicts."""

AUDIO_CHANNELS = audio_features.FEATURE_DIM
BEAT_COLUMNS = slice(AUDIO_CHANNELS - 2, AUDIO_CHANNELS)  # beat_sin, beat_cos

ROTATION_CHANNELS = 6 * len(BODY)
ROOT_CHANNELS = 4
CONTACT_CHANNELS = len(FOOT_JOINTS)
MOTION_CHANNELS = ROTATION_CHANNELS + ROOT_CHANNELS + CONTACT_CHANNELS
ROTATIONS = slice(0, ROTATION_CHANNELS)
HEIGHT = ROTATION_CHANNELS
VELOCITY = slice(ROTATION_CHANNELS + 1, ROTATION_CHANNELS + 3)
TURN = ROTATION_CHANNELS + 3
CONTACTS = slice(ROTATION_CHANNELS + ROOT_CHANNELS, MOTION_CHANNELS)


def genre_index(name: str) -> int:
    """Index of genre ``name`` in :data:`GENRES` (``MotionError`` kind "invalid" if unknown)."""
    try:
        return GENRES.index(name)
    except ValueError:
        raise MotionError(f"unknown genre {name!r}; genres are {', '.join(GENRES)}") from None


def genre_vector(name: str | None = None, probabilities: np.ndarray | None = None) -> np.ndarray:
    """``(len(GENRES),)`` float32: one-hot of ``name``, or ``probabilities`` over
    :data:`MUSIC_GENRES` placed in their slots."""
    out = np.zeros(len(GENRES), dtype=np.float32)
    if name is not None:
        out[genre_index(name)] = 1.0
    elif probabilities is not None:
        out[: len(MUSIC_GENRES)] = np.asarray(probabilities, dtype=np.float32)
    return out


# --------------------------------------------------------------------------- audio


def song_features(
    samples: np.ndarray,
    sr: int,
    num_frames: int,
    *,
    offset: float = 0.0,
    beats: np.ndarray | None = None,
    tempo: float | None = None,
) -> np.ndarray:
    """Audio input ``(num_frames, AUDIO_CHANNELS)`` float32 for frames at 30 fps starting
    ``offset`` seconds into the song ``samples (N,)`` (negative: silence before the song).

    ``beats`` (seconds on the song's clock, default: tracked on the excerpt itself) give the
    beat phase, so an excerpt of a song gets the phase of the whole song's beat grid.
    """
    start = int(round(offset * sr))
    stop = start + int(np.ceil(num_frames / FPS * sr)) + 1
    lo, hi = max(start, 0), max(min(stop, len(samples)), 0)
    excerpt = np.zeros(stop - start, dtype=np.float32)
    if hi > lo:
        excerpt[lo - start : hi - start] = samples[lo:hi]
    if not np.any(excerpt):
        excerpt[0] = 1e-6  # all silence: features at the floor, no beats
    feats = audio_features.frame_features(excerpt, sr, FPS, num_frames)
    x = feats.matrix()
    if beats is not None:
        beats = np.asarray(beats, dtype=np.float64) - offset
        period = 60.0 / tempo if tempo else None
        phase = beat_tracking.beat_phase(beats, num_frames, FPS, period=period).astype(np.float64)
        x[:, BEAT_COLUMNS] = np.stack(
            [np.sin(2 * np.pi * phase), np.cos(2 * np.pi * phase)], axis=-1
        )
    return x


def drop_beats(x: np.ndarray) -> np.ndarray:
    """A copy of audio input ``x (..., AUDIO_CHANNELS)`` with the beat marked unknown (0, 0)."""
    out = np.array(x, dtype=np.float32, copy=True)
    out[..., BEAT_COLUMNS] = 0.0
    return out


# --------------------------------------------------------------------------- motion


@dataclass(frozen=True)
class Encoded:
    """``features (F, MOTION_CHANNELS)`` float32, and where decoding must start to land where
    the clip started: ``start (3,)`` the root on the floor at frame 0, ``heading`` radians."""

    features: np.ndarray
    start: np.ndarray
    heading: float


CONTACT_HEIGHT = 0.12  # leg lengths above the local ground
CONTACT_SPEED = 0.3  # leg lengths per second
GROUND_WINDOW_SECONDS = 2.0


def dance_contacts(gpos: np.ndarray, fps: float = FPS) -> np.ndarray:
    """Foot contacts ``(F, 4)`` bool of Foot_L, Toes_L, Foot_R, Toes_R from canonical global
    positions ``gpos (F, 22, 3)``: slow on the floor (under ``CONTACT_SPEED``) and within
    ``CONTACT_HEIGHT`` of the local ground, the lowest foot joint's height over a sliding
    ``GROUND_WINDOW_SECONDS`` (the Dance with Melody floor drifts by several cm within a
    dance, so ``contacts.foot_contacts``'s clip-wide ground level misses most contacts)."""
    gpos = np.asarray(gpos, dtype=np.float64)
    feet = gpos[:, FOOT_JOINTS]
    if len(gpos) == 0:
        return np.zeros((0, len(FOOT_JOINTS)), dtype=bool)
    ground = CT.local_ground(feet[..., 1], fps, GROUND_WINDOW_SECONDS)
    low = feet[..., 1] - ground[:, None] < CONTACT_HEIGHT * LEG
    slow = CT.horizontal_speed(feet, fps) < CONTACT_SPEED * LEG
    min_frames = max(1, int(round(CT.MIN_CONTACT_SECONDS * fps)))
    return CT.clean_contacts(low & slow, min_frames)


FLOOR_SMOOTH_SECONDS = 0.5  # Gaussian sigma of a take's floor, followed as it drifts


def level_floor(motion: Motion) -> Motion:
    """A canonical dance with its floor at height 0 throughout: the lowest foot joint's
    height over a sliding ``GROUND_WINDOW_SECONDS``, smoothed, taken off the hips. The Dance
    with Melody takes' floors lie up to 13 cm apart and drift within a take; measured on
    one clip-wide ground level, a foot on a raised stretch of floor counts as in the air."""
    from scipy.ndimage import gaussian_filter1d

    feet = K.global_positions(motion)[:, FOOT_JOINTS, 1]
    floor = CT.local_ground(feet, motion.fps, GROUND_WINDOW_SECONDS)
    floor = gaussian_filter1d(floor, FLOOR_SMOOTH_SECONDS * motion.fps, mode="nearest")
    lpos = motion.lpos.copy()
    lpos[:, HIPS, 1] -= floor
    return motion.replace(lpos=lpos)


def encode(motion: Motion, contacts: np.ndarray | None = None) -> Encoded:
    """The encoding of a canonical motion at 30 fps; ``contacts (F, 4)`` default to
    :func:`dance_contacts`."""
    C.check_motion(motion, "dance features")
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    dirs = K.facing_directions(gpos, *FACING_JOINTS, smooth=FACING_SMOOTH)
    face = K.facing_rotations(dirs)
    lrot = motion.lrot[:, BODY].copy()
    lrot[:, 0] = rot.mul(rot.inv(face), grot[:, HIPS])
    hips = gpos[:, HIPS]
    root = hips * np.array([1.0, 0.0, 1.0])
    vel, turn = K.root_velocities(root, face, motion.fps)
    if contacts is None:
        contacts = dance_contacts(gpos, motion.fps)
    frames = motion.num_frames
    features = np.concatenate(
        [
            rot.to_6d(lrot).reshape(frames, -1),
            hips[:, 1:2] / LEG,
            vel / LEG,
            turn[:, None],
            np.asarray(contacts, dtype=np.float64).reshape(frames, CONTACT_CHANNELS),
        ],
        axis=-1,
    )
    return Encoded(
        features.astype(np.float32), root[0].copy(), float(np.arctan2(dirs[0, 0], dirs[0, 2]))
    )


def decode(
    features: np.ndarray,
    start: np.ndarray | None = None,
    heading: float = 0.0,
    fps: float = FPS,
) -> tuple[Motion, np.ndarray]:
    """A canonical motion and contacts ``(F, 4)`` bool from raw (not standardised) features
    ``(F, MOTION_CHANNELS)``.

    The root starts at ``start`` (on the floor; the origin by default) facing ``heading``;
    the step from frame t to t + 1 is frame t's velocity turned by frame t's heading.
    """
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != MOTION_CHANNELS:
        raise MotionError(f"dance features must be (frames, {MOTION_CHANNELS}), got {x.shape}")
    frames = len(x)
    root, face = K.integrate_root(x[:, VELOCITY] * LEG, x[:, TURN], fps, start, heading)
    lrot = rot.identity((frames, len(C.JOINTS)))
    body = rot.from_6d(x[:, ROTATIONS].reshape(frames, len(BODY), 6))
    lrot[:, BODY] = body
    lrot[:, HIPS] = rot.mul(face, body[:, 0])
    lrot = _continuous(lrot)
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 0] = 0.0
    lpos[:, HIPS] = root + np.stack(
        [np.zeros(frames), x[:, HEIGHT] * LEG, np.zeros(frames)], axis=-1
    )
    return Motion(C.SKELETON, float(fps), lrot, lpos), x[:, CONTACTS] > 0.5


def _continuous(q: np.ndarray) -> np.ndarray:
    """``rot.make_continuous`` along frames, without its loop over frames: each quaternion's
    sign is the running product of the signs of the dot products with its predecessor (the
    same flips, but where a dot product is exactly 0)."""
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    signs = np.cumprod(np.where(dots < 0.0, -1.0, 1.0), axis=0)
    out = q.copy()
    out[1:] *= signs[..., None]
    return out


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class DanceStats:
    """Per-channel ``mean``/``std`` of the audio ``(AUDIO_CHANNELS,)`` and motion
    ``(MOTION_CHANNELS,)`` inputs, float32."""

    audio_mean: np.ndarray
    audio_std: np.ndarray
    motion_mean: np.ndarray
    motion_std: np.ndarray

    @staticmethod
    def fit(audio_features: list[np.ndarray], motion_features: list[np.ndarray]) -> DanceStats:
        """Statistics of lists of ``(F_i, C)`` arrays. Beat sin/cos keep mean 0, std 1 (so
        (0, 0) stays "unknown"); contacts map to -1/+1; every std is floored at 1e-2 of
        the channel group's mean std."""
        a = np.concatenate([np.asarray(f, dtype=np.float64) for f in audio_features])
        m = np.concatenate([np.asarray(f, dtype=np.float64) for f in motion_features])
        a_mean, a_std = a.mean(axis=0), a.std(axis=0)
        a_mean[BEAT_COLUMNS], a_std[BEAT_COLUMNS] = 0.0, 1.0
        m_mean, m_std = m.mean(axis=0), m.std(axis=0)
        m_mean[CONTACTS], m_std[CONTACTS] = 0.5, 0.5
        a_std = np.maximum(a_std, 1e-2 * a_std.mean())
        m_std = np.maximum(m_std, 1e-2 * m_std.mean())
        return DanceStats(*(v.astype(np.float32) for v in (a_mean, a_std, m_mean, m_std)))

    def normalize_audio(self, x: np.ndarray) -> np.ndarray:
        return ((np.asarray(x, np.float32) - self.audio_mean) / self.audio_std).astype(np.float32)

    def normalize_motion(self, x: np.ndarray) -> np.ndarray:
        return ((np.asarray(x, np.float32) - self.motion_mean) / self.motion_std).astype(np.float32)

    def denormalize_motion(self, z: np.ndarray) -> np.ndarray:
        return (np.asarray(z, np.float32) * self.motion_std + self.motion_mean).astype(np.float32)

    def arrays(self) -> dict[str, np.ndarray]:
        return {
            "audio_mean": self.audio_mean,
            "audio_std": self.audio_std,
            "motion_mean": self.motion_mean,
            "motion_std": self.motion_std,
        }

    def save(self, path: str | Path, **extra: np.ndarray) -> None:
        """``.npz`` with the four arrays (and ``extra`` ones, e.g. start poses)."""
        np.savez(path, **self.arrays(), **extra)

    @staticmethod
    def from_arrays(arrays: dict[str, np.ndarray]) -> DanceStats:
        stats = DanceStats(
            *(np.asarray(arrays[k], np.float32) for k in ("audio_mean", "audio_std",
                                                          "motion_mean", "motion_std"))
        )  # fmt: skip
        if stats.audio_mean.shape != (AUDIO_CHANNELS,) or stats.motion_mean.shape != (
            MOTION_CHANNELS,
        ):
            raise MotionError("dance statistics have the wrong number of channels")
        return stats

    @staticmethod
    def load(path: str | Path) -> DanceStats:
        with np.load(path, allow_pickle=False) as z:
            return DanceStats.from_arrays({k: z[k] for k in z.files})


# --------------------------------------------------------------------------- post-processing


def smooth_features(x: np.ndarray, cutoff_hz: float = 6.0, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass (``scipy.signal``) of rotation and root channels of raw
    features ``(F, MOTION_CHANNELS)``; contacts are kept. Short clips are returned as they are."""
    x = np.asarray(x, dtype=np.float64)
    b, a = butter(order, cutoff_hz / (0.5 * FPS))
    pad = 3 * max(len(a), len(b))
    if len(x) <= pad:
        return x.astype(np.float32)
    out = x.copy()
    out[:, : CONTACTS.start] = filtfilt(b, a, x[:, : CONTACTS.start], axis=0)
    return out.astype(np.float32)


STALL_SECONDS = 5.0
STALL_FRACTION = 0.3
"""A stall: :data:`STALL_SECONDS` of music in which the dance's mean joint speed stays below
this share of its median (what a viewer notices as the dancer stopping)."""
KEEP_MOVING_SECONDS = 2.0
KEEP_MOVING_TRIGGER = 0.5
KEEP_MOVING_FRACTION = 0.65
KEEP_MOVING_MARGIN_SECONDS = 0.5
KEEP_MOVING_PIECE_SECONDS = 3.0
KEEP_MOVING_STRIDE = 2


def window_means(x: np.ndarray, length: int) -> np.ndarray:
    """Mean of ``x (N,)`` over the ``length`` samples centred on each sample (edges: the
    window shrinks)."""
    from scipy.ndimage import uniform_filter1d

    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return x
    return uniform_filter1d(x, max(1, min(length, x.size)), mode="nearest")


def stalls(speed: np.ndarray, fps: float, playing: np.ndarray | None = None) -> np.ndarray:
    """Start times ``(S,)`` (seconds) of the :data:`STALL_SECONDS` windows of joint ``speed
    (N,)`` (``motion.beat_warp.joint_speed``) whose mean is below :data:`STALL_FRACTION` of
    the median speed, among windows in which the music plays throughout (``playing (N,)``
    bool, default: everywhere)."""
    speed = np.asarray(speed, dtype=np.float64)
    length = int(round(STALL_SECONDS * fps))
    if speed.size < length or speed.size == 0:
        return np.zeros(0)
    playing = np.ones(speed.size, bool) if playing is None else np.asarray(playing, bool)
    median = float(np.median(speed[playing])) if playing.any() else 0.0
    sums = np.concatenate([[0.0], np.cumsum(speed)])
    means = (sums[length:] - sums[:-length]) / length
    silent = np.concatenate([[0], np.cumsum(~playing)])
    music = (silent[length:] - silent[:-length]) == 0
    return np.flatnonzero(music & (means < STALL_FRACTION * median)) / float(fps)


def keep_moving(
    features: np.ndarray, playing: np.ndarray | None = None, fps: float = FPS
) -> tuple[np.ndarray, Motion]:
    """Raw features ``(F, MOTION_CHANNELS)`` of a dance whose slow stretches are filled with
    its own livelier moves, and the motion they decode to (:func:`decode`).

    The network's autoregressive loop can settle into a near standstill (5 cm/s against a
    median of 30), which a viewer sees as the dancer stopping, and no gain on so little
    motion brings it back. Where the mean joint speed over :data:`KEEP_MOVING_SECONDS`
    falls below :data:`KEEP_MOVING_TRIGGER` of the dance's median while the music plays
    (``playing (F,)`` bool, default everywhere), the stretch below
    :data:`KEEP_MOVING_FRACTION` of it around that place (with
    :data:`KEEP_MOVING_MARGIN_SECONDS` either side) is cross-faded, over the margins and
    in pieces of :data:`KEEP_MOVING_PIECE_SECONDS`, into the equally long stretch of the
    dance that moves most steadily (highest slowest window) away from any slow stretch.
    Features are root-relative (velocities, facing frame), so a copied stretch joins on;
    the beat warp afterwards puts it on the beat."""
    x = np.asarray(features, dtype=np.float32).copy()
    playing = np.ones(len(x), bool) if playing is None else np.asarray(playing, bool)
    motion, _ = decode(x, fps=fps)
    length = int(round(KEEP_MOVING_SECONDS * fps))
    if len(x) < 4 * length or not playing.any():
        return x, motion
    # joint speed at every other frame: enough for means over seconds, at half the FK
    sampled = motion.replace(lrot=motion.lrot[::KEEP_MOVING_STRIDE],
                             lpos=motion.lpos[::KEEP_MOVING_STRIDE])  # fmt: skip
    speed = np.repeat(BW.joint_speed(K.global_positions(sampled), fps / KEEP_MOVING_STRIDE),
                      KEEP_MOVING_STRIDE)  # fmt: skip
    speed = np.pad(speed, (0, max(0, len(x) - len(speed))), mode="edge")[: len(x)]
    median = float(np.median(speed[playing]))
    local = window_means(speed, length)
    if not (playing & (local < KEEP_MOVING_TRIGGER * median)).any():
        return x, motion
    margin = int(round(KEEP_MOVING_MARGIN_SECONDS * fps))
    piece = int(round(KEEP_MOVING_PIECE_SECONDS * fps))
    slow = _runs(playing & (local < KEEP_MOVING_FRACTION * median))
    lively = np.ones(len(x), bool)
    for a, b in slow:
        lively[max(0, a - margin) : b + margin] = False
    source = x.copy()
    for a, b in slow:
        if not (local[a:b] < KEEP_MOVING_TRIGGER * median).any():
            continue
        # pieces of at most KEEP_MOVING_PIECE_SECONDS, each cross-faded into the next
        for p in range(a, b, piece):
            lo, hi = max(0, p - margin), min(len(x), min(p + piece, b) + margin)
            best, best_floor = None, -1.0
            for start in range(0, len(x) - (hi - lo) + 1, margin):
                span = slice(start, start + hi - lo)
                if lively[span].all() and local[span].min() > best_floor:
                    best, best_floor = start, float(local[span].min())
            if best is None:
                continue
            n = hi - lo
            ramp = np.clip(np.minimum(np.arange(n) + 1, n - np.arange(n)) / margin, 0.0, 1.0)
            weight = (ramp * ramp * (3.0 - 2.0 * ramp))[:, None]
            x[lo:hi] = (1.0 - weight) * x[lo:hi] + weight * source[best : best + n]
    return x, decode(x, fps=fps)[0]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of the runs of True in ``mask (N,)``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))  # fmt: skip

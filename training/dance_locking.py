"""A Dance with Melody dance beside its song, and the measures of how its motion locks to the
music (``training.dance_alignment`` runs the study on them): the tempo-locking index of the
step cycle against the song's beat grid over a scan of rates, with the halves test, the
beat-alignment score over a scan of lags, the Rayleigh test of the kinematic beats' phase
and the cross-correlation of joint speed with the onset envelope."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion import beat_warp as BW
from motion import spectral

SOURCE_FPS = 25.0
# Beats per step cycle: a waltz bar; the Latin and tango basic figures repeat every 2 beats
# in joint speed (their 4-beat figures alternate feet).
CYCLE_BEATS = {"cha-cha": 2, "rumba": 2, "tango": 2, "waltz": 3}
# Above this tracked tempo the tracker has caught the half-beat: the cycle has twice the beats.
DOUBLE_TIME_BPM = 150.0
LAGS = np.round(np.arange(-3.0, 3.0 + 1e-9, 0.01), 2)
RATES = np.round(np.arange(0.90, 1.10 + 1e-9, 0.0025), 4)
DETREND_SECONDS = 1.0  # Gaussian high-pass of the locking signals


@dataclass
class Dance:
    """One pair: raw marker positions ``points (F, 23, 3)`` at 25 fps, the song's beats ``(B,)``
    and onset envelope ``(T,)`` at ``spectral.ONSET_FRAME_RATE`` over the whole song."""

    name: str
    genre: str
    points: np.ndarray
    start_position: int
    end_position: int
    beats: np.ndarray
    tempo: float
    onset: np.ndarray
    song_seconds: float

    @property
    def config_offset(self) -> float:
        return self.start_position / SOURCE_FPS

    @property
    def cycle(self) -> int:
        k = CYCLE_BEATS[self.genre]
        return 2 * k if self.tempo > DOUBLE_TIME_BPM else k

    @property
    def beat_period(self) -> float:
        return float(np.median(np.diff(self.beats)))

    @property
    def duration(self) -> float:
        return len(self.points) / SOURCE_FPS


def _standard(x: np.ndarray) -> np.ndarray:
    x = x - gaussian_filter1d(x, DETREND_SECONDS * SOURCE_FPS, mode="nearest")
    return x / max(float(x.std()), 1e-12)


def motion_signals(points: np.ndarray) -> dict[str, np.ndarray]:
    """Locking signals ``(F - 1,)`` at the instants ``(i + 0.5) / 25``: joint speed and pelvis
    height (marker 2), detrended and standardised."""
    speed = BW.joint_speed(points, SOURCE_FPS)
    height = 0.5 * (points[1:, 2, 1] + points[:-1, 2, 1])
    return {"speed": _standard(speed), "height": _standard(height)}


def locking(x: np.ndarray, times: np.ndarray, beats: np.ndarray, cycle: int) -> tuple[float, float]:
    """``(L, phase)``: the locking index of ``x (N,)`` at ``times (N,)`` (audio clock) to the
    ``cycle``-beat phase of ``beats``, and the locked phase in cycles ``[-0.5, 0.5)``."""
    angle = 2.0 * np.pi * BW.beat_position(beats, times) / cycle
    z = np.sum(x * np.exp(-1j * angle))
    return float(2.0 * abs(z) ** 2 / max(float(np.sum(x * x)), 1e-12)), float(
        np.angle(z) / (2.0 * np.pi)
    )


def rate_scan(
    x: np.ndarray, t: np.ndarray, offset: float, beats: np.ndarray, cycle: int
) -> np.ndarray:
    """``L`` over :data:`RATES` for motion times ``t (N,)``."""
    return np.array([locking(x, offset + r * t, beats, cycle)[0] for r in RATES])


def _refine(values: np.ndarray, grid: np.ndarray) -> float:
    j = int(np.argmax(values))
    if 0 < j < len(values) - 1:
        left, mid, right = values[j - 1], values[j], values[j + 1]
        curvature = left - 2 * mid + right
        if curvature < 0:
            return float(grid[j] + 0.5 * (left - right) / curvature * (grid[1] - grid[0]))
    return float(grid[j])


def _wrap(x: float) -> float:
    return float((x + 0.5) % 1.0 - 0.5)


def split_halves(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    half = len(t) // 2
    return np.arange(half), np.arange(half, len(t))


@dataclass
class Lock:
    signal: str
    rate: float  # best rate (refined)
    peak: float  # L at the best rate
    median: float  # median L across the rate scan
    phase: float  # locked phase at the best rate (cycles)
    half_phase_error: float  # half 2's phase minus the one predicted from half 1 (cycles)
    half_rate: float  # rate fitted on half 1

    @property
    def ratio(self) -> float:
        return self.peak / max(self.median, 1e-12)


def tempo_lock(d: Dance, offset: float) -> Lock:
    """The stronger of the two signals' locking (by peak over median), with the halves test:
    rate and phase fitted on the first half predict the phase of the second half."""
    best = None
    t = (np.arange(len(d.points) - 1) + 0.5) / SOURCE_FPS
    for name, x in motion_signals(d.points).items():
        scan = rate_scan(x, t, offset, d.beats, d.cycle)
        rate = _refine(scan, RATES)
        peak, phase = locking(x, offset + rate * t, d.beats, d.cycle)
        first, second = split_halves(t)
        half_scan = rate_scan(x[first], t[first], offset, d.beats, d.cycle)
        half_rate = _refine(half_scan, RATES)
        _, phase1 = locking(x[first], offset + half_rate * t[first], d.beats, d.cycle)
        _, phase2 = locking(x[second], offset + half_rate * t[second], d.beats, d.cycle)
        lock = Lock(
            name,
            rate,
            peak,
            float(np.median(scan)),
            phase,
            _wrap(phase2 - phase1),
            half_rate,
        )
        if best is None or lock.ratio > best.ratio:
            best = lock
    assert best is not None
    return best


def lock_at(d: Dance, signal: str, offset: float, rate: float) -> tuple[float, float, float]:
    """``(L, phase, half_phase_error)`` of ``signal`` at a fixed alignment."""
    x = motion_signals(d.points)[signal]
    t = (np.arange(len(x)) + 0.5) / SOURCE_FPS
    value, phase = locking(x, offset + rate * t, d.beats, d.cycle)
    first, second = split_halves(t)
    _, p1 = locking(x[first], offset + rate * t[first], d.beats, d.cycle)
    _, p2 = locking(x[second], offset + rate * t[second], d.beats, d.cycle)
    return value, phase, _wrap(p2 - p1)


def kin_beats(d: Dance) -> np.ndarray:
    """Kinematic beats of the raw markers, seconds of motion time (25 fps clock)."""
    return BW.kinematic_beats(d.points, SOURCE_FPS)


def rayleigh(kin_audio: np.ndarray, beats: np.ndarray) -> tuple[float, float]:
    """``(R, Z)``: resultant length of the kinematic beats' phases within the beat and the
    Rayleigh statistic ``n R^2`` (p about ``exp(-Z)``)."""
    inside = BW.within_beats(kin_audio, beats)
    if inside.size == 0:
        return 0.0, 0.0
    phase = BW.beat_position(beats, inside)
    r = float(abs(np.mean(np.exp(2j * np.pi * phase))))
    return r, float(len(inside) * r * r)


def lag_scan(kin: np.ndarray, offset: float, rate: float, beats: np.ndarray) -> np.ndarray:
    """Beat-alignment scores ``(len(LAGS),)`` of motion-time kinematic beats ``kin``."""
    base = offset + rate * kin
    return np.array([BW.beat_alignment_score(base + lag, beats) for lag in LAGS])


def onset_xcorr(d: Dance, offset: float, rate: float) -> tuple[float, float]:
    """Peak normalised cross-correlation of joint speed with the onset envelope over
    :data:`LAGS` and its lag (seconds; positive: the music comes later than config says)."""
    speed = gaussian_filter1d(BW.joint_speed(d.points, SOURCE_FPS), 1.0)
    speed = (speed - speed.mean()) / max(float(speed.std()), 1e-12)
    t = (np.arange(len(speed)) + 0.5) / SOURCE_FPS
    env_t = np.arange(len(d.onset)) / spectral.ONSET_FRAME_RATE
    values = []
    for lag in LAGS:
        env = np.interp(offset + lag + rate * t, env_t, d.onset, left=0.0, right=0.0)
        env = (env - env.mean()) / max(float(env.std()), 1e-12)
        values.append(float(np.mean(speed * env)))
    values = np.array(values)
    j = int(np.argmax(values))
    return float(values[j]), float(LAGS[j])


def beat_phase_lag(cycle_phase: float, cycle: int, beat_period: float, psi: float) -> float:
    """Seconds to add to a dance's offset so that its step cycle's locked phase, within the
    beat, becomes ``psi`` beats (the nearest such shift, within half a beat)."""
    return beat_period * _wrap(cycle_phase * cycle - psi)

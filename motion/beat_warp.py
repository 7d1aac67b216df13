"""Dance timing: kinematic beats, the beat-alignment score, its chance level, and a time warp
that moves a motion's kinematic beats onto the music's beats.

Definitions (what the project means by "beat alignment", stated once):

- **Joint speed** ``(F - 1,)``: mean over the given joints of ``|p[i + 1] - p[i]| * fps``,
  reported at the instant ``(i + 0.5) / fps`` (between the two frames).
- **Kinematic beats**: strict local minima of the joint speed after a Gaussian of
  ``SMOOTH_SECONDS`` (Bailando's ``gaussian_filter(kinetic_vel, 5)`` at 60 fps is 1/12 s);
  AIST++ (``motion_peak_onehot``) uses the unsmoothed sum with a 10-frame neighbourhood
  instead. Times in seconds, refined to a fraction of a frame by a parabola through the
  minimum and its neighbours.
- **Beat-alignment score** (AIST++, Li et al. 2021, eq. in sec. 5.1): the mean over kinematic
  beats ``t_k`` of ``exp(-d_k^2 / (2 sigma^2))``, ``d_k`` the distance to the nearest music
  beat, ``sigma = 0.05`` s (AIST++: 3 frames at 60 fps). Kinematic beats further than half a
  beat period outside the span of the music beats are left out (the beat tracker trims quiet
  intros and endings; a dance moving there is not off the beat). Bailando's code averages
  the other way round (over music beats, nearest kinematic beat); :func:`beat_alignment_score`
  does that with ``over="music"``.
- **Chance level** (:func:`shifted_grid_baseline`): the same kinematic beats scored against the
  music's beat grid with every beat moved by the same random fraction ``u ~ U(0, 1)`` of its
  following interval: same tempo and tempo changes, unrelated phase.

:func:`warp_to_beats` retimes a motion (slerp/linear resampling through a monotone
piecewise-linear time map) so that kinematic beats near a music beat land on it, with the
local playback rate kept within ``[1 / max_stretch, max_stretch]`` per pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion import kinematics as K
from motion.skeleton import Motion

SIGMA_SECONDS = 0.05
SMOOTH_SECONDS = 1.0 / 12.0
WARP_MAX_STRETCH = 1.35
"""Playback rate :func:`warp_to_beats` allows between anchors: within ``[1 / s, s]``."""
WARP_ITERATIONS = 8
WARP_MAX_SHARE = 0.5
"""A kinematic beat is moved onto a music beat up to this share of the beat period away (and
``max_shift`` seconds): at half, any kinematic beat may go to its nearest beat."""


def joint_speed(gpos: np.ndarray, fps: float) -> np.ndarray:
    """Mean joint speed ``(F - 1,)`` (units per second) of positions ``gpos (F, J, 3)``; value
    ``i`` is the speed between frames ``i`` and ``i + 1``."""
    gpos = np.asarray(gpos, dtype=np.float64)
    if len(gpos) < 2:
        return np.zeros(0)
    return np.linalg.norm(np.diff(gpos, axis=0), axis=-1).mean(axis=-1) * float(fps)


def kinematic_beats(
    gpos: np.ndarray, fps: float, *, smooth_seconds: float = SMOOTH_SECONDS
) -> np.ndarray:
    """Kinematic beat times ``(K,)`` in seconds from frame 0 of ``gpos (F, J, 3)`` at ``fps``:
    local minima of the smoothed joint speed (see the module docstring)."""
    speed = joint_speed(gpos, fps)
    return speed_minima(speed, fps, smooth_seconds=smooth_seconds)


def speed_minima(
    speed: np.ndarray, fps: float, *, smooth_seconds: float = SMOOTH_SECONDS
) -> np.ndarray:
    """Times ``(K,)`` (s) of the strict local minima of ``speed (N,)``, sample ``i`` being the
    instant ``(i + 0.5) / fps``, after Gaussian smoothing of ``smooth_seconds``."""
    v = np.asarray(speed, dtype=np.float64)
    if v.size < 3:
        return np.zeros(0)
    if smooth_seconds > 0:
        v = gaussian_filter1d(v, smooth_seconds * fps, mode="nearest")
    mid = v[1:-1]
    idx = np.flatnonzero((mid < v[:-2]) & (mid < v[2:])) + 1
    left, centre, right = v[idx - 1], v[idx], v[idx + 1]
    curvature = left - 2.0 * centre + right
    offset = np.where(
        curvature > 0, 0.5 * (left - right) / np.where(curvature > 0, curvature, 1), 0
    )
    return (idx + np.clip(offset, -0.5, 0.5) + 0.5) / float(fps)


def _nearest_distance(times: np.ndarray, grid: np.ndarray) -> np.ndarray:
    j = np.searchsorted(grid, times)
    before = grid[np.clip(j - 1, 0, len(grid) - 1)]
    after = grid[np.clip(j, 0, len(grid) - 1)]
    return np.minimum(np.abs(times - before), np.abs(times - after))


def within_beats(times: np.ndarray, beats: np.ndarray) -> np.ndarray:
    """The ``times (K,)`` that lie within half a median beat period of the beats' span."""
    times = np.asarray(times, dtype=np.float64)
    beats = np.sort(np.asarray(beats, dtype=np.float64))
    if beats.size < 2:
        return times[:0]
    half = 0.5 * float(np.median(np.diff(beats)))
    return times[(times >= beats[0] - half) & (times <= beats[-1] + half)]


def beat_alignment_score(
    kin_beats: np.ndarray,
    music_beats: np.ndarray,
    sigma: float = SIGMA_SECONDS,
    *,
    over: str = "kinematic",
) -> float:
    """Beat-alignment score in ``[0, 1]`` (AIST++; see the module docstring).

    ``kin_beats (K,)`` and ``music_beats (B,)`` in seconds on the same clock. ``over=
    "kinematic"`` (AIST++'s definition, the default) averages over the kinematic beats within
    the music's span; ``over="music"`` (Bailando's code) over the music beats within the
    motion's span. 0.0 when either side has nothing to score.
    """
    kin = np.sort(np.asarray(kin_beats, dtype=np.float64))
    music = np.sort(np.asarray(music_beats, dtype=np.float64))
    if over == "kinematic":
        probe, grid = within_beats(kin, music), music
    elif over == "music":
        if kin.size == 0:
            return 0.0
        probe, grid = music[(music >= kin[0]) & (music <= kin[-1])], kin
    else:
        raise ValueError(f"over must be 'kinematic' or 'music', got {over!r}")
    if probe.size == 0 or grid.size == 0:
        return 0.0
    d = _nearest_distance(probe, grid)
    return float(np.mean(np.exp(-(d**2) / (2.0 * sigma**2))))


def shifted_grid(music_beats: np.ndarray, fraction: float) -> np.ndarray:
    """Beats ``(B - 1,)`` each moved forward by ``fraction`` of its following interval."""
    beats = np.sort(np.asarray(music_beats, dtype=np.float64))
    return beats[:-1] + float(fraction) * np.diff(beats)


@dataclass(frozen=True)
class Baseline:
    """Chance level of a score: ``mean`` and ``std`` over ``draws`` shifted grids."""

    mean: float
    std: float
    draws: int

    def z(self, score: float) -> float:
        """How many standard deviations ``score`` lies above the mean."""
        return (score - self.mean) / self.std if self.std > 0 else 0.0


def shifted_grid_baseline(
    kin_beats: np.ndarray,
    music_beats: np.ndarray,
    *,
    draws: int = 200,
    seed: int = 0,
    sigma: float = SIGMA_SECONDS,
) -> Baseline:
    """Beat-alignment scores of ``kin_beats`` against ``draws`` beat grids shifted by random
    fractions of a beat (seeded): the chance level of :func:`beat_alignment_score`."""
    if np.asarray(music_beats).size < 3:
        return Baseline(0.0, 0.0, 0)
    fractions = np.random.default_rng(seed).random(draws)
    scores = [
        beat_alignment_score(kin_beats, shifted_grid(music_beats, u), sigma) for u in fractions
    ]
    return Baseline(float(np.mean(scores)), float(np.std(scores)), draws)


def alignment(motion: Motion, music_beats: np.ndarray, *, draws: int = 50) -> tuple[float, float]:
    """The project's beat alignment of ``motion`` against ``music_beats (B,)`` (seconds from
    its frame 0): the AIST++ score of its kinematic beats and its chance level, the mean
    over ``draws`` shifted grids (:func:`shifted_grid_baseline`, seed 0). ``(0, 0)`` with
    under three beats. The service's warning and ``make eval-dance`` both report this."""
    if np.asarray(music_beats).size < 3:
        return 0.0, 0.0
    kin = kinematic_beats(K.global_positions(motion), motion.fps)
    chance = shifted_grid_baseline(kin, music_beats, draws=draws).mean
    return beat_alignment_score(kin, music_beats), chance


def beat_position(beats: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Continuous beat index ``(N,)`` at ``times (N,)``: ``k`` at beat ``k``, linear between
    beats, extrapolated with the median period outside them."""
    beats = np.sort(np.asarray(beats, dtype=np.float64))
    times = np.asarray(times, dtype=np.float64)
    if beats.size < 2:
        raise ValueError("need at least two beats")
    period = float(np.median(np.diff(beats)))
    index = np.arange(len(beats), dtype=np.float64)
    out = np.interp(times, beats, index)
    out = np.where(times < beats[0], (times - beats[0]) / period, out)
    return np.where(times > beats[-1], index[-1] + (times - beats[-1]) / period, out)


# --------------------------------------------------------------------------- time warp


@dataclass(frozen=True)
class WarpResult:
    """A retimed motion and what the warp did: ``anchors (A, 2)`` pairs of (output time,
    source time) in seconds that it moved onto beats."""

    motion: Motion
    anchors: np.ndarray


def match_beats(
    kin_beats: np.ndarray,
    music_beats: np.ndarray,
    *,
    max_shift: float = 0.2,
    max_stretch: float = 1.25,
    max_share: float = WARP_MAX_SHARE,
) -> np.ndarray:
    """Monotone anchor pairs ``(A, 2)`` (music beat, kinematic beat) in seconds.

    Each kinematic beat is paired with its nearest music beat when they are within
    ``max_shift`` seconds (and ``max_share`` of the local beat period); a music beat takes at most
    one kinematic beat (the nearest); pairs whose time map between neighbours would need a
    playback rate outside ``[1 / max_stretch, max_stretch]`` are dropped, greedily in time.
    """
    kin = np.sort(np.asarray(kin_beats, dtype=np.float64))
    music = np.sort(np.asarray(music_beats, dtype=np.float64))
    if kin.size == 0 or music.size < 2:
        return np.zeros((0, 2))
    j = np.clip(np.searchsorted(music, kin), 1, len(music) - 1)
    nearest = np.where(np.abs(kin - music[j - 1]) <= np.abs(kin - music[j]), j - 1, j)
    period = np.interp(kin, music[1:], np.diff(music))
    dist = np.abs(kin - music[nearest])
    ok = (dist <= max_shift) & (dist <= period * max_share)
    best: dict[int, tuple[float, float]] = {}
    for k, m, d in zip(kin[ok], nearest[ok], dist[ok], strict=True):
        if int(m) not in best or d < abs(best[int(m)][1] - music[m]):
            best[int(m)] = (float(music[m]), float(k))
    pairs = sorted(best.values())
    kept: list[tuple[float, float]] = []
    for out_t, src_t in pairs:
        if kept:
            d_out, d_src = out_t - kept[-1][0], src_t - kept[-1][1]
            if d_out <= 0 or d_src <= 0 or not 1 / max_stretch <= d_src / d_out <= max_stretch:
                continue
        kept.append((out_t, src_t))
    return np.array(kept).reshape(-1, 2)


def warp_to_beats(
    motion: Motion,
    music_beats: np.ndarray,
    *,
    kin_beats: np.ndarray | None = None,
    max_shift: float = 0.2,
    max_stretch: float = WARP_MAX_STRETCH,
    iterations: int = WARP_ITERATIONS,
    max_share: float = WARP_MAX_SHARE,
) -> WarpResult:
    """``motion`` retimed so that its kinematic beats near music beats fall on them.

    Music beat times are seconds from the motion's frame 0. The output has the same frame
    count and rate; output frame ``i`` shows the source pose at ``s(i / fps)``, ``s`` a
    monotone map composed of ``iterations`` passes, each a cubic (PCHIP, so the playback
    rate changes smoothly) through the anchors of :func:`match_beats` and the clip's ends
    (:func:`_pinned_knots`). A warp moves the speed minima a little, so each
    pass finds the kinematic beats afresh (the first time ``kin_beats`` when given) on the
    speed of the motion warped so far, ``v(s(t)) s'(t)``: the source's joint speed through
    the map, so the motion itself is resampled once. ``anchors`` are those of the first
    pass.
    """
    from scipy.interpolate import PchipInterpolator

    fps = float(motion.fps)
    frames = motion.num_frames
    speed = joint_speed(K.global_positions(motion), fps)
    if frames < 3:
        return WarpResult(motion, np.zeros((0, 2)))
    mids = (np.arange(frames - 1) + 0.5) / fps
    out_t = np.arange(frames) / fps
    src_t = out_t.copy()  # the composed map, sampled at the output frames
    first, moved = None, False
    for i in range(max(1, iterations)):
        kin = kin_beats if (i == 0 and kin_beats is not None) else None
        if kin is None:
            at = np.interp(mids, out_t, src_t)
            rate = np.diff(src_t) * fps
            kin = speed_minima(np.interp(at, mids, speed) * rate, fps)
        anchors = match_beats(kin, music_beats, max_shift=max_shift, max_stretch=max_stretch,
                              max_share=max_share)  # fmt: skip
        first = anchors if first is None else first
        if len(anchors) < 2:
            break
        knots_out, knots_src = _pinned_knots(anchors, out_t[-1])
        step = PchipInterpolator(knots_out, knots_src)(out_t)
        src_t = _through(src_t, out_t, step)
        moved = True
    warped = K.resample_at(motion, src_t * fps, fps) if moved else motion
    return WarpResult(warped, first if first is not None else np.zeros((0, 2)))


def _pinned_knots(anchors: np.ndarray, end: float) -> tuple[np.ndarray, np.ndarray]:
    """A pass's knots: its ``anchors (A, 2)`` (output, source seconds) and the clip's ends,
    0 and ``end``, each mapped onto itself, so the map neither starts before the first
    frame nor runs past the last one. Continued with slope 1 instead, a pass that ended
    its anchors at a fast rate ran the source out seconds early and froze the dance's end.
    An anchor on an end stands for the pinned knot."""
    out, src = anchors[:, 0], anchors[:, 1]
    keep = (out > 0.0) & (out < end) & (src > 0.0) & (src < end)
    return (np.concatenate([[0.0], out[keep], [end]]),
            np.concatenate([[0.0], src[keep], [end]]))  # fmt: skip


def _through(mapped: np.ndarray, times: np.ndarray, query: np.ndarray) -> np.ndarray:
    """A map sampled as ``mapped (N,)`` at ``times (N,)`` evaluated at ``query``: linear
    between samples, slope 1 beyond them (as every pass's map is beyond its anchors)."""
    out = np.interp(query, times, mapped)
    out = np.where(query < times[0], mapped[0] + (query - times[0]), out)
    return np.where(query > times[-1], mapped[-1] + (query - times[-1]), out)

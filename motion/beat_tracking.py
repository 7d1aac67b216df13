"""Tempo, beats, downbeats and pulses of an onset envelope, and a beat metric.

Beat tracking follows Ellis (2007), "Beat tracking by dynamic programming", as librosa
implements it (tempo from the autocorrelation of the onset envelope weighted by a
log-normal prior around 120 bpm; then dynamic programming over beat positions), written in
numpy. Envelopes come from :mod:`motion.spectral` at :data:`~motion.spectral.ONSET_FRAME_RATE`
(about 43 Hz, independent of the motion's fps), so the beat times of a song do not depend on
the motion frame rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from motion.spectral import BEAT_LOW_HZ, ONSET_FRAME_RATE, ONSET_MEL_HZ, beat_levels, rise_envelope

MAX_BPM = 200.0
"""Fastest beat :func:`estimate_tempo` reports: listeners tap beats up to about here."""
LOCAL_TEMPO_SECONDS = 12.0
"""Span of the autocorrelation that sets the local tempo the beat tracker follows."""
LOCAL_TEMPO_RANGE = 1.35
"""The local tempo stays within this factor of the song's tempo (its octave)."""
GENRE_TEMPO = {"cha-cha": 122.6, "rumba": 97.8, "tango": 127.8, "waltz": 86.1}
"""The tempo (bpm of the beat a dancer steps) each ballroom genre is danced at: the geometric
mean of the danced, else tracked, tempi of the shared songs used to train the dance model
(``python -m training.dance_tempo --fit``). A waltz is counted in threes at 84-90."""
GENRE_TEMPO_OCTAVES = 0.25
"""Width of the genre's tempo prior (log-normal, in octaves): a level an octave off the
genre's tempo pays 8 nats of periodicity. 0.15 to 0.7 octaves put the same shared songs at
their danced tempo (``training.dance_tempo``)."""
_ACF_CHUNK_FRAMES = 1024  # autocorrelation frames per batch: bounds the FFT matrix
_ACF_STRIDE = 2  # autocorrelations of every other frame's excerpt: 8-s windows overlap anyway


@dataclass(frozen=True)
class Tempo:
    """The tempo of an onset envelope: ``bpm`` for the whole song and ``period (T,)``, the
    local beat period in envelope frames at every frame; ``autocorrelation`` the sums of the
    envelope's autocorrelation over blocks of ``block`` frames it was found in (so that
    :func:`at_level` chooses another metrical level without computing them again)."""

    bpm: float
    period: np.ndarray
    autocorrelation: np.ndarray | None = None
    block: int = 0


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
    level_bpm: float | None = None,
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
    envelope has no onsets or is too short to hold one beat at ``max_bpm``.

    With ``level_bpm`` (the tempo a dance genre steps, :data:`GENRE_TEMPO`) the metrical
    level is chosen as a listener who knows the dance would: among the global tempo's
    :data:`METRICAL_LEVELS` (it, its half, its third), the one whose periodicity and a
    log-normal prior of :data:`GENRE_TEMPO_OCTAVES` around ``level_bpm`` score best. Only
    the tracked pulse's own levels compete: a prior alone over every lag moved synthetic
    3/4 songs onto two-thirds of their beat.
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
    if not np.isfinite(log_prior).any():  # too short to hold one beat at max_bpm
        return Tempo(0.0, np.zeros(0))
    lag = _refined_peak(np.log1p(1e6 * mean_ac) + log_prior, int(np.argmax(log_prior)))
    period = _local_periods(sums, lag, block, len(onset), frame_rate)
    found = Tempo(float(60.0 * frame_rate / lag), period, sums, block)
    if level_bpm is None:
        return found
    return at_level(found, level_bpm, frame_rate, max_bpm=max_bpm)


def at_level(
    tempo: Tempo, level_bpm: float, frame_rate: float = ONSET_FRAME_RATE, *, max_bpm=MAX_BPM
) -> Tempo:
    """``tempo`` at the metrical level a listener expecting ``level_bpm`` taps (see
    :func:`tempo_curve`); ``tempo`` itself when that is its own level."""
    if tempo.bpm <= 0 or tempo.autocorrelation is None:
        return tempo
    frames = len(tempo.period)
    mean_ac = tempo.autocorrelation.sum(axis=0) / frames
    periodicity = np.log1p(1e6 * mean_ac)
    lag = 60.0 * frame_rate / tempo.bpm
    levels = METRICAL_LEVELS
    if tresillo_ratio(mean_ac, lag) >= TRESILLO_RATIO:
        levels = METRICAL_LEVELS + TRESILLO_LEVELS
    level = _metrical_level(periodicity, lag, level_bpm, frame_rate, max_bpm, levels)
    if level is None:
        return tempo
    period = _local_periods(tempo.autocorrelation, level, tempo.block, frames, frame_rate)
    return Tempo(float(60.0 * frame_rate / level), period, tempo.autocorrelation, tempo.block)


METRICAL_LEVELS = (1.0 / 3.0, 0.5, 1.0)
"""The tempi, as multiples of the tracked one, a genre's level is chosen among: the tracked
pulse or a slower level of it, so that every step still falls on a beat. Faster levels were
tried: a cha-cha or a tango on a 70-bpm song then stepped every half beat, off the swung
eighths and the half-time grooves of the generated test songs (alignment 1.4x its shifted
grids); where a song accents its half beats, :func:`pulses` adds them anyway."""


TRESILLO_LEVELS = (0.75 / 3.0, 0.75 / 2.0, 0.75)
"""The levels a tresillo song adds: its 3-3-2 rhythm (dotted eighths, then an eighth) puts
the tracked pulse on the dotted eighth, at 4/3 of the beat a dancer steps."""
TRESILLO_RATIO = 0.8
"""A song is heard as a tresillo when the first four multiples of 4/3 of its tracked
period are, on average, this periodic against the tracked period's own four: 0.84-0.91 on
the shared songs danced at 3/4 of their tracked pulse, at most 0.82 on the others and 0.74
on the generated test songs (triplets)."""
TRESILLO_MULTIPLES = 4


def tresillo_ratio(mean_ac: np.ndarray, lag: float) -> float:
    """How periodic an envelope (its mean normalised autocorrelation ``mean_ac``) is at
    :data:`TRESILLO_MULTIPLES` multiples of 4/3 of ``lag`` (frames) against those of ``lag``
    itself: a pulse explains its own multiples, a tresillo's dotted eighths do not, its
    beat (4/3 of them) does."""

    def comb(period: float) -> float | None:
        values = []
        for k in range(1, TRESILLO_MULTIPLES + 1):
            centre = int(round(k * period))
            if centre + 2 > len(mean_ac):
                return None
            values.append(float(mean_ac[max(centre - 1, 1) : centre + 2].max()))
        return float(np.mean(values))

    own, slower = comb(lag), comb(4.0 * lag / 3.0)
    if own is None or slower is None or own <= 0:
        return 0.0
    return slower / own


def _metrical_level(
    periodicity: np.ndarray,
    lag: float,
    level_bpm: float,
    frame_rate: float,
    max_bpm: float,
    levels: tuple[float, ...] = METRICAL_LEVELS,
) -> float | None:
    """The lag, among ``levels`` of ``lag``'s tempo, that a listener expecting
    ``level_bpm`` taps (see :func:`tempo_curve`), refined to its own peak; None for
    ``lag`` itself."""
    best, best_score = None, -np.inf
    for level in levels:
        candidate = lag / level
        bpm = 60.0 * frame_rate / candidate
        centre = int(round(candidate))
        if bpm >= max_bpm or not 3 <= centre < len(periodicity) - 3:
            continue
        prior = -0.5 * (np.log2(bpm / level_bpm) / GENRE_TEMPO_OCTAVES) ** 2
        near = periodicity[centre - 1 : centre + 2]
        score = float(near.max()) + prior
        if score > best_score:
            peak = centre - 1 + int(np.argmax(near))
            best = (
                None
                if level == 1.0
                else peak - 2 + _refined_peak(periodicity[peak - 2 : peak + 3], 2)
            )
            best_score = score
    return best


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
    chunk = max(block, _ACF_CHUNK_FRAMES // block * block)
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
    genre: str | None = None,
    tempo: Tempo | None = None,
) -> tuple[float, np.ndarray]:
    """Tempo (bpm) and beat times ``(B,)`` in seconds from an onset envelope ``(T,)``.

    Ellis (2007) dynamic programming, as in ``librosa.beat.beat_track``: beat ``i``'s score
    is the onset strength there (smoothed by a Gaussian of a 32nd of a beat) plus the best
    score of a previous beat ``d`` frames back, penalised by ``tightness * log(d / p)^2``;
    the path is traced back from the last strong beat and weak beats at either end are
    dropped. ``p`` is the local period of :func:`tempo_curve` (so a tempo change is
    followed), or constant when ``bpm`` is given (then this is librosa's tracker). With a
    ``genre`` (a key of :data:`GENRE_TEMPO`) the metrical level is the one a dancer of that
    genre steps (:func:`tempo_curve`'s ``level_bpm``). ``tempo``: the envelope's
    :func:`tempo_curve`, when already known. Returns ``(0.0, [])`` when there are no onsets
    or no tempo is found. Frame ``t`` of the envelope is time ``t / frame_rate``.
    """
    onset = np.asarray(onset, dtype=np.float64)
    if onset.ndim != 1:
        raise ValueError(f"onset must be 1-D (T,), got shape {onset.shape}")
    if onset.size < 2 or not onset.any():
        return 0.0, np.zeros(0)
    if bpm is None:
        estimate = tempo or tempo_curve(onset, frame_rate)
        if genre in GENRE_TEMPO:
            estimate = at_level(estimate, GENRE_TEMPO[genre], frame_rate)
        bpm_found, periods = estimate.bpm, estimate.period
        if bpm_found <= 0:
            return 0.0, np.zeros(0)
    else:
        bpm_found = float(bpm)
        if not bpm_found > 0:
            raise ValueError(f"bpm must be positive, got {bpm}")
        periods = np.full(len(onset), frame_rate * 60.0 / bpm_found)
    period = frame_rate * 60.0 / bpm_found
    local = _local_score(onset / (onset.std(ddof=1) + 1e-30), period)
    backlink, cumulative = _beat_dp(local, periods, tightness)
    beats = _backtrack(backlink, _last_beat(cumulative))
    beats = _trim_weak_ends(local, beats)
    return bpm_found, beats / frame_rate


def _local_score(onset: np.ndarray, period: float) -> np.ndarray:
    """``onset`` smoothed by a Gaussian of a 32nd of a beat, one value per frame (numpy's
    ``mode="same"`` returns the kernel's length for an envelope shorter than the kernel)."""
    reach = round(period)
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) * 32.0 / period) ** 2)
    return np.convolve(onset, kernel, mode="full")[reach : reach + len(onset)]


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
    levels = beat_levels(mel) if levels is None else levels
    low = ONSET_MEL_HZ < BEAT_LOW_HZ
    low_rise = rise_envelope(levels[:, low], lambda rise: rise.mean(axis=1))
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


def pulses(
    beats: np.ndarray,
    envelope: np.ndarray,
    frame_rate: float = ONSET_FRAME_RATE,
    *,
    genre: str | None = None,
):
    """The music's strong pulses ``(P,)`` (seconds): ``beats (B,)``, and the points halfway
    between them when the song accents those nearly as much (:data:`HALF_BEAT_SHARE`) and
    the doubled tempo stays under :data:`MAX_BPM`. A song at 180 bpm whose kick and snare
    alternate on every beat is tracked at 90 (the prior's octave, which 90-bpm rumbas with
    strong eighths need too): its dance should still land on every hit. A waltz steps the
    three beats of its bars, not their halves: for ``genre="waltz"`` the beats alone."""
    beats = np.asarray(beats, dtype=np.float64)
    envelope = np.asarray(envelope, dtype=np.float64)
    if beats.size < 2 or envelope.size == 0 or genre == "waltz":
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

"""What music-motion alignment the Dance with Melody pairs really have.

``python -m training.dance_alignment`` prints the study and ``--write PATH`` saves the
per-dance table (default ``training/dance_alignment.json``, committed) that the dance
training reads through :func:`load_table` / :func:`alignment_for`. ``docs/dance_alignment.md``
explains the method and the findings.

Clocks. A dance's raw markers are at 25 fps (data README); motion time ``t`` is seconds from
its frame 0 at 25 fps. An alignment maps it onto the song: ``audio_time = offset + rate * t``.
``config.json`` read literally is ``offset = start_position / 25``, ``rate = 1``.

Measures, per dance (``motion.beat_warp`` defines the beat-alignment score):

1. beat alignment (AIST++) at the config alignment, its shifted-grid chance level (mean, std)
   and the Rayleigh test of the kinematic beats' phase within the beat (locked or not, at
   any lag);
2. the lag in -3..+3 s that maximises the score, and whether it holds up: fitted on the first
   half of the dance, scored on the second half against that half's chance level;
3. cross-correlation of joint speed with the onset envelope over the same lags;
4. tempo locking: the step cycle (``CYCLE_BEATS`` beats: a waltz bar, a Latin basic step)
   of the motion against the song's beat grid. ``x`` (joint speed or pelvis height, detrended)
   is demodulated by the music's cycle phase ``2 pi beat_position(offset + rate * t) / k``:
   ``L(rate) = 2 |sum x e^{-i phase}|^2 / sum x^2`` (the periodogram at the song's own,
   tempo-following cycle frequency: about 1 for noise, about N for a locked sinusoid). The
   rate is scanned (0.90..1.10), the best one refined, and the locked phase must hold from the
   first half of the dance to the second;
5. the same scores under the other readings of the units (``start_position`` as 30 fps frames
   or seconds, motion really at 24 or 30 fps), pooled.

Verdicts: ``verified`` (locked at the global rate: stable phase, most of the locking),
``rate-corrected`` (locked only at its own rate: the dancer's tempo differs from the song's),
``unverified``. The lag within a beat cannot be measured from kinematic beats (they do not
concentrate at any phase of the beat): the training lag puts every dance's step cycle at the
same phase of the beat, ``psi`` beats, chosen where the pooled score of the verified dances is
highest and checked leave-one-dance-out.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import audio_decode, beat_tracking, spectral
from motion import beat_warp as BW
from training.dance_locking import (
    LAGS,
    RATES,
    SOURCE_FPS,
    Dance,
    beat_phase_lag,
    kin_beats,
    lag_scan,
    lock_at,
    motion_signals,
    onset_xcorr,
    rate_scan,
    rayleigh,
    tempo_lock,
)

REPO = Path(__file__).resolve().parent.parent
TABLE_PATH = Path(__file__).resolve().parent / "dance_alignment.json"
TABLE_VERSION = 1

LOCK_RATIO_MIN = 10.0  # L at the best rate over its median across rates: a real peak
RATE_CORRECTION_MAX = 0.07  # a dancer off the song's tempo by more is not dancing to it
PHASE_TOLERANCE = 0.125  # cycles: half 2's phase predicted from half 1 within this
KEEP_FRACTION = 0.5  # verified: L at the global rate at least this share of the best L
HYPOTHESES = (
    ("config: start/25 s, motion 25 fps", "start25", 1.0),
    ("start_position as 30 fps frames", "start30", 1.0),
    ("start_position in seconds", "start_s", 1.0),
    ("offset sign flipped", "neg25", 1.0),
    ("motion really 24 fps", "start25", 25.0 / 24.0),
    ("motion really 30 fps", "start25", 25.0 / 30.0),
)


# --------------------------------------------------------------------------- inputs


def _music_cache(folder: Path) -> Path:
    from training.data import cache_dir

    st = (folder / "audio.mp3").stat()
    key = hashlib.sha256(f"{folder.name}:{st.st_size}:{int(st.st_mtime)}:2".encode()).hexdigest()
    return cache_dir() / f"dance_music_{folder.name}_{key[:12]}.npz"


def analyse_music(folder: Path) -> dict[str, np.ndarray]:
    """Beats, tempo and onset envelope of a whole song (cached in the data cache)."""
    path = _music_cache(folder)
    if path.exists():
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    samples, sr = audio_decode.decode(folder / "audio.mp3")
    onset = spectral.onset_strength(samples, sr, aggregate=np.mean)
    # the study's tracker, librosa's (median rise of dB, one tempo up to 320 bpm): the table
    # and the training's beat phase were made with it; the service tracks beats on the
    # kick and bass (spectral.beat_onset_strength)
    median = spectral.onset_strength(samples, sr, aggregate=np.median)
    tempo, beats = beat_tracking.track_beats(
        median, bpm=beat_tracking.estimate_tempo(median, max_bpm=320.0)
    )
    out = {
        "beats": beats,
        "tempo": np.array(tempo),
        "onset": onset.astype(np.float32),
        "seconds": np.array(len(samples) / sr),
    }
    np.savez(path, **out)
    return out


def load_dances(root: Path | None = None, names: list[str] | None = None) -> list[Dance]:
    """Every Dance with Melody pair with motion and audio (or only ``names``)."""
    from training.data import DWM_GENRES, data_dir, read_dwm_folder

    root = (root or data_dir()) / "dance-with-melody"
    folders = sorted(p for p in root.glob("DANCE_*") if (p / "skeletons.json").exists())
    dances = []
    for folder in folders:
        if names and folder.name not in names:
            continue
        points, config = read_dwm_folder(folder)
        music = analyse_music(folder)
        dances.append(
            Dance(
                name=folder.name,
                genre=DWM_GENRES[folder.name.split("_")[1]],
                points=points,
                start_position=int(config["start_position"]),
                end_position=int(config["end_position"]),
                beats=np.asarray(music["beats"], dtype=np.float64),
                tempo=float(music["tempo"]),
                onset=np.asarray(music["onset"], dtype=np.float64),
                song_seconds=float(music["seconds"]),
            )
        )
    return dances


# --------------------------------------------------------------------------- measures


def hypothesis_offset(d: Dance, kind: str) -> float:
    return {
        "start25": d.start_position / 25.0,
        "start30": d.start_position / 30.0,
        "start_s": float(d.start_position),
        "neg25": -d.start_position / 25.0,
    }[kind]


# --------------------------------------------------------------------------- the study


def study_dance(d: Dance, seed: int = 0) -> dict:
    """Everything the table holds for one dance except what needs the global rate."""
    kin = kin_beats(d)
    off = d.config_offset
    cfg = BW.beat_alignment_score(off + kin, d.beats)
    base = BW.shifted_grid_baseline(off + kin, d.beats, seed=seed)
    r, z = rayleigh(off + kin, d.beats)
    scan = lag_scan(kin, off, 1.0, d.beats)
    best = int(np.argmax(scan))
    half = len(kin) // 2
    first = lag_scan(kin[:half], off, 1.0, d.beats)
    lag1 = float(LAGS[int(np.argmax(first))])
    second = off + lag1 + kin[half:]
    half2 = BW.beat_alignment_score(second, d.beats)
    half2_base = BW.shifted_grid_baseline(second, d.beats, seed=seed)
    xc, xc_lag = onset_xcorr(d, off, 1.0)
    lock = tempo_lock(d, off)
    return {
        "genre": d.genre,
        "frames_25fps": len(d.points),
        "duration_s": round(d.duration, 2),
        "config": {"start_position": d.start_position, "end_position": d.end_position},
        "config_offset_s": round(off, 3),
        "tempo_bpm": round(d.tempo, 2),
        "beat_period_s": round(d.beat_period, 4),
        "cycle_beats": d.cycle,
        "kinematic_beats": len(kin),
        "bas_config": round(cfg, 4),
        "bas_shifted_mean": round(base.mean, 4),
        "bas_shifted_std": round(base.std, 4),
        "bas_config_z": round(base.z(cfg), 2),
        "rayleigh_r": round(r, 3),
        "rayleigh_z": round(z, 2),
        "best_lag_s": float(LAGS[best]),
        "bas_best_lag": round(float(scan[best]), 4),
        "half1_lag_s": lag1,
        "bas_half2_at_half1_lag": round(half2, 4),
        "bas_half2_shifted_mean": round(half2_base.mean, 4),
        "bas_half2_shifted_std": round(half2_base.std, 4),
        "onset_xcorr_peak": round(xc, 3),
        "onset_xcorr_lag_s": xc_lag,
        "lock_signal": lock.signal,
        "lock_rate": round(lock.rate, 4),
        "lock_peak": round(lock.peak, 1),
        "lock_ratio": round(lock.ratio, 1),
        "lock_phase_cycles": round(lock.phase, 3),
        "lock_half1_rate": round(lock.half_rate, 4),
        "lock_half_phase_error": round(lock.half_phase_error, 3),
    }


def global_rate(rows: dict[str, dict]) -> float:
    """Median best rate of the strongly locked dances whose halves agree: the clock ratio."""
    rates = [
        r["lock_rate"]
        for r in rows.values()
        if r["lock_ratio"] >= LOCK_RATIO_MIN and abs(r["lock_half_phase_error"]) <= PHASE_TOLERANCE
    ]
    return float(np.median(rates)) if rates else 1.0


def classify(d: Dance, row: dict, rate: float) -> None:
    """Add the verdict and the alignment the training uses to ``row`` (in place)."""
    value, phase, half_err = lock_at(d, row["lock_signal"], d.config_offset, rate)
    row["global_rate_lock"] = round(value, 1)
    row["global_rate_lock_share"] = round(value / max(row["lock_peak"], 1e-12), 3)
    row["global_rate_half_phase_error"] = round(half_err, 3)
    row["global_rate_phase_cycles"] = round(phase, 3)
    strong = row["lock_ratio"] >= LOCK_RATIO_MIN
    own_stable = abs(row["lock_half_phase_error"]) <= PHASE_TOLERANCE
    if strong and value >= KEEP_FRACTION * row["lock_peak"] and abs(half_err) <= PHASE_TOLERANCE:
        row["verdict"], use_rate, use_phase = "verified", rate, phase
    elif strong and own_stable and abs(row["lock_rate"] - 1.0) <= RATE_CORRECTION_MAX:
        row["verdict"], use_rate, use_phase = "rate-corrected", row["lock_rate"], None
    else:
        row["verdict"], use_rate, use_phase = "unverified", 1.0, None
    if use_phase is None and row["verdict"] == "rate-corrected":
        _, use_phase, _ = lock_at(d, row["lock_signal"], d.config_offset, use_rate)
    row["use_rate"] = round(use_rate, 4)
    row["use_cycle_phase"] = None if use_phase is None else round(use_phase, 4)


def pooled_psi(dances: list[Dance], rows: dict[str, dict], names: list[str]) -> np.ndarray:
    """Mean beat-alignment score over ``names`` for each psi in ``PSI_GRID``."""
    scores = np.zeros(len(PSI_GRID))
    for name in names:
        d, row = next(x for x in dances if x.name == name), rows[name]
        kin = kin_beats(d)
        for i, psi in enumerate(PSI_GRID):
            lag = beat_phase_lag(row["use_cycle_phase"], d.cycle, d.beat_period, psi)
            off = d.config_offset + lag
            scores[i] += BW.beat_alignment_score(off + row["use_rate"] * kin, d.beats)
    return scores / max(len(names), 1)


PSI_GRID = np.round(np.arange(0.0, 1.0, 0.02), 2)


def run_study(dances: list[Dance], seed: int = 0, log=print) -> dict:
    """The whole study: per-dance rows, the global rate, verdicts, psi and the hypotheses."""
    rows = {}
    for d in dances:
        rows[d.name] = study_dance(d, seed)
        r = rows[d.name]
        log(
            f"{d.name:10s} cfg {r['bas_config']:.3f} (chance {r['bas_shifted_mean']:.3f}"
            f"+-{r['bas_shifted_std']:.3f}) best {r['bas_best_lag']:.3f}@{r['best_lag_s']:+.2f}"
            f" half2 {r['bas_half2_at_half1_lag']:.3f} rayleighZ {r['rayleigh_z']:.1f}"
            f" xcorr {r['onset_xcorr_peak']:.3f}@{r['onset_xcorr_lag_s']:+.2f}"
            f" lock {r['lock_signal']} rate {r['lock_rate']:.4f} ratio {r['lock_ratio']:.0f}"
            f" half-err {r['lock_half_phase_error']:+.3f}"
        )
    rate = global_rate(rows)
    for d in dances:
        classify(d, rows[d.name], rate)
    usable = [n for n, r in rows.items() if r["verdict"] != "unverified"]
    verified = [n for n, r in rows.items() if r["verdict"] == "verified"]

    # psi: pooled over the verified dances; leave-one-dance-out check on every usable one
    pooled = pooled_psi(dances, rows, verified)
    psi = float(PSI_GRID[int(np.argmax(pooled))])
    for d in dances:
        row = rows[d.name]
        if row["use_cycle_phase"] is None:
            row["use_lag_s"] = 0.0
            continue
        others = [n for n in verified if n != d.name]
        loo = pooled_psi(dances, rows, others) if others else pooled
        psi_loo = float(PSI_GRID[int(np.argmax(loo))])
        kin = kin_beats(d)
        lag_loo = beat_phase_lag(row["use_cycle_phase"], d.cycle, d.beat_period, psi_loo)
        aligned = d.config_offset + lag_loo + row["use_rate"] * kin
        base = BW.shifted_grid_baseline(aligned, d.beats, seed=seed)
        row["psi_loo"] = psi_loo
        row["bas_loo"] = round(BW.beat_alignment_score(aligned, d.beats), 4)
        row["bas_loo_shifted_mean"] = round(base.mean, 4)
        row["bas_loo_shifted_std"] = round(base.std, 4)
        row["use_lag_s"] = round(
            beat_phase_lag(row["use_cycle_phase"], d.cycle, d.beat_period, psi), 4
        )
    for row in rows.values():
        row["use_offset_s"] = round(row["config_offset_s"] + row["use_lag_s"], 4)
        row["beat_phase_trusted"] = row["verdict"] != "unverified"

    hypotheses = []
    fitted = (f"fitted global rate {rate:.4f} (motion at {SOURCE_FPS / rate:.2f} fps)", "start25")
    for label, kind, h_rate in (*HYPOTHESES, (*fitted, rate)):
        bas, base_mean, shares, stable = [], [], [], 0
        for d in dances:
            if kind == "neg25" and d.start_position == 0:
                continue
            off = hypothesis_offset(d, kind)
            kin = off + h_rate * kin_beats(d)
            bas.append(BW.beat_alignment_score(kin, d.beats))
            base_mean.append(BW.shifted_grid_baseline(kin, d.beats, seed=seed).mean)
            row = rows[d.name]
            value, _, err = lock_at(d, row["lock_signal"], off, h_rate)
            shares.append(value / max(row["lock_peak"], 1e-12))
            stable += int(value >= KEEP_FRACTION * row["lock_peak"] and abs(err) <= PHASE_TOLERANCE)
        hypotheses.append(
            {
                "hypothesis": label,
                "rate": round(h_rate, 4),
                "dances": len(bas),
                "bas_mean": round(float(np.mean(bas)), 4),
                "bas_shifted_mean": round(float(np.mean(base_mean)), 4),
                "lock_share_mean": round(float(np.mean(shares)), 3),
                "locked_dances": stable,
            }
        )
    loo = [r for r in rows.values() if "bas_loo" in r]
    summary = {
        "dances": len(rows),
        "bas_config_mean": round(float(np.mean([r["bas_config"] for r in rows.values()])), 4),
        "bas_config_shifted_mean": round(
            float(np.mean([r["bas_shifted_mean"] for r in rows.values()])), 4
        ),
        "rayleigh_significant_p05": sum(r["rayleigh_z"] > 3.0 for r in rows.values()),
        "half2_above_chance_1sd": sum(
            r["bas_half2_at_half1_lag"] > r["bas_half2_shifted_mean"] + r["bas_half2_shifted_std"]
            for r in rows.values()
        ),
        "onset_xcorr_peak_max": max(r["onset_xcorr_peak"] for r in rows.values()),
        "global_rate": round(rate, 4),
        "global_rate_fps": round(SOURCE_FPS / rate, 3),
        "verified": verified,
        "rate_corrected": [n for n, r in rows.items() if r["verdict"] == "rate-corrected"],
        "unverified": [n for n, r in rows.items() if r["verdict"] == "unverified"],
        "psi_beats": psi,
        "psi_pooled_bas": round(float(pooled.max()), 4),
        "psi_pooled_bas_min": round(float(pooled.min()), 4),
        "loo_bas_mean": round(float(np.mean([r["bas_loo"] for r in loo])), 4) if loo else None,
        "loo_shifted_mean": (
            round(float(np.mean([r["bas_loo_shifted_mean"] for r in loo])), 4) if loo else None
        ),
        "usable": usable,
    }
    return {
        "version": TABLE_VERSION,
        "definition": {
            "clock": "audio_time = use_offset_s + use_rate * motion_time (motion time: seconds "
            "from frame 0 of the 25 fps source, = canonical frame / 30)",
            "bas": "AIST++: mean over kinematic beats (local minima of mean joint speed, "
            "Gaussian 1/12 s) of exp(-d^2 / (2 * 0.05^2)), d to the nearest librosa-equivalent "
            "beat; kinematic beats outside the beats' span (+- half a beat) left out",
            "chance": "shifted grid: every beat moved by the same random fraction of its "
            "interval, 200 draws",
            "lock": "periodogram of detrended joint speed or pelvis height at the song's "
            "cycle phase (cycle_beats), over rates 0.90..1.10",
        },
        "summary": summary,
        "hypotheses": hypotheses,
        "dances": rows,
    }


# --------------------------------------------------------------------------- for training


def load_table(path: Path | str = TABLE_PATH) -> dict:
    """The committed study table (``--write``)."""
    with open(path) as f:
        table = json.load(f)
    if table.get("version") != TABLE_VERSION:
        raise ValueError(f"{path}: table version {table.get('version')}, need {TABLE_VERSION}")
    return table


@dataclass(frozen=True)
class Alignment:
    """Where a dance sits in its song: ``audio_time = offset + rate * motion_time``;
    ``trusted``: whether its beat phase may teach timing."""

    offset: float
    rate: float
    trusted: bool
    verdict: str


def alignment_for(name: str, table: dict | None = None) -> Alignment | None:
    """The alignment the study chose for dance ``name`` (None when it is not in the table)."""
    table = load_table() if table is None else table
    row = table["dances"].get(name)
    if row is None:
        return None
    return Alignment(
        float(row["use_offset_s"]),
        float(row["use_rate"]),
        bool(row["beat_phase_trusted"]),
        str(row["verdict"]),
    )


# --------------------------------------------------------------------------- plot


def _png(path: Path, rgb: np.ndarray) -> None:
    """Write ``rgb (H, W, 3)`` uint8 as a PNG (no plotting library needed)."""
    import struct
    import zlib

    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    Path(path).write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )  # fmt: skip


PLOT_COLOURS = {"verified": (0, 150, 60), "rate-corrected": (230, 130, 0),
                "unverified": (150, 150, 150)}  # fmt: skip


def plot_locking(dances: list[Dance], table: dict, path: Path, size=(1000, 560)) -> None:
    """Each dance's locking ``L(rate) / max`` over :data:`RATES` (x: 0.90 to 1.10; y: 0 to
    1), coloured by verdict (green verified, orange rate-corrected, grey unverified);
    vertical lines at rate 1 (config, black), the fitted global rate (blue) and 25/24
    (motion at 24 fps, red)."""
    width, height = size
    img = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 40, width - 20, 20, height - 30

    def px(rate, value):
        x = left + (rate - RATES[0]) / (RATES[-1] - RATES[0]) * (right - left)
        y = bottom - value * (bottom - top)
        return x, y

    def line(x0, y0, x1, y1, colour, thick=1):
        n = int(max(abs(x1 - x0), abs(y1 - y0))) + 1
        for t in np.linspace(0, 1, n + 1):
            x, y = int(round(x0 + t * (x1 - x0))), int(round(y0 + t * (y1 - y0)))
            img[max(y - thick + 1, 0) : y + thick, max(x - thick + 1, 0) : x + thick] = colour

    line(left, bottom, right, bottom, (0, 0, 0))
    line(left, top, left, bottom, (0, 0, 0))
    for r in np.arange(0.90, 1.1001, 0.05):
        x, _ = px(r, 0)
        line(x, bottom, x, bottom + 8, (0, 0, 0))
    rate = table["summary"]["global_rate"]
    for r, colour in ((1.0, (0, 0, 0)), (rate, (40, 80, 230)), (25 / 24, (220, 30, 30))):
        x, _ = px(r, 0)
        line(x, top, x, bottom, colour)
    order = {"unverified": 0, "rate-corrected": 1, "verified": 2}
    for d in sorted(dances, key=lambda d: order[table["dances"][d.name]["verdict"]]):
        row = table["dances"][d.name]
        x = motion_signals(d.points)[row["lock_signal"]]
        t = (np.arange(len(x)) + 0.5) / SOURCE_FPS
        scan = rate_scan(x, t, d.config_offset, d.beats, d.cycle)
        scan = scan / max(float(scan.max()), 1e-12)
        pts = [px(r, v) for r, v in zip(RATES, scan, strict=True)]
        colour = PLOT_COLOURS[row["verdict"]]
        for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:], strict=True):
            line(x0, y0, x1, y1, colour, 2 if row["verdict"] == "verified" else 1)
    _png(path, img)


# --------------------------------------------------------------------------- CLI


def _print_table(result: dict) -> None:
    s = result["summary"]
    print()
    print(
        f"mean BAS at config {s['bas_config_mean']:.3f} vs shifted grids "
        f"{s['bas_config_shifted_mean']:.3f}; Rayleigh p<0.05 in {s['rayleigh_significant_p05']}"
        f" of {s['dances']}; best-lag transfers to half 2 (>1 sd) in "
        f"{s['half2_above_chance_1sd']}; onset xcorr max {s['onset_xcorr_peak_max']:.3f}"
    )
    print(f"global rate {s['global_rate']:.4f} (motion clock {s['global_rate_fps']:.2f} fps)")
    print(f"verified: {s['verified']}")
    print(f"rate-corrected: {s['rate_corrected']}")
    print(f"unverified: {s['unverified']}")
    print(
        f"psi {s['psi_beats']:.2f} beats: pooled BAS {s['psi_pooled_bas']:.3f} "
        f"(worst psi {s['psi_pooled_bas_min']:.3f}); leave-one-out BAS {s['loo_bas_mean']} vs "
        f"chance {s['loo_shifted_mean']}"
    )
    for h in result["hypotheses"]:
        print(f"  {h}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", type=Path, nargs="?", const=TABLE_PATH, default=None,
                        help=f"save the table (default {TABLE_PATH.relative_to(REPO)})")  # fmt: skip
    parser.add_argument("--dance", action="append", help="only these dances (repeatable)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot", type=Path, help="PNG of each dance's locking over rates")
    args = parser.parse_args(argv)
    dances = load_dances(names=args.dance)
    if not dances:
        print("no Dance with Melody data found (set MOTION_DATA_DIR)", file=sys.stderr)
        return 1
    result = run_study(dances, seed=args.seed)
    _print_table(result)
    if args.write:
        args.write.write_text(json.dumps(result, indent=1, allow_nan=False) + "\n")
        print(f"wrote {args.write}")
    if args.plot:
        plot_locking(dances, result, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

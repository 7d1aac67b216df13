"""``motion-style-train check LIB``: whether a library (``training.library``) can be trained
on, said before anything trains.

It reads every clip and maps its rig as the service does (``motion.retarget.make_rig``:
method, confidence and naming convention, one line per distinct skeleton), lists the
style x content pairs the paired stage can learn from (an action performed in at least two
styles), and names every problem: rows of ``labels.csv`` that are wrong, files missing or
unreadable, rigs that cannot be mapped, styles with fewer than :data:`MIN_TAKES` takes or
sharing no action with any other style. It estimates the hours the one command takes here
and on a GPU, from the training steps per second it measures on this machine and the
translator's recorded rate on a GPU (:data:`GPU_TRANSLATOR_STEPS_PER_S`). The clips it
converted are cached, so a training that follows does not read them again.
"""

from __future__ import annotations

import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from training import library as L

MIN_TAKES = 2  # a style needs one take to learn from and one more for its code to mean it
LOW_CONFIDENCE = 0.5  # a rig mapped less surely than this is worth a look
WINDOW = 64  # frames a content window spans (training.translator.fit.TrainConfig.window)
# The translator's steps per second on a GPU, one run (docs/translator.md: the schedule's
# 6,000 steps in 6.8 minutes on a lent H200 shared by four runs, 14.7 steps/s each).
GPU_TRANSLATOR_STEPS_PER_S = 14.7
FAST_STEPS = 5000  # per style (training.fast_style)
ALIGN_SECONDS_PER_PAIR = 60.0 / 21010  # Bandai's 21,010 pairs in about a minute here


@dataclass
class CheckReport:
    library: str
    clips: int = 0
    frames: int = 0
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    rigs: list[dict] = field(default_factory=list)
    styles: dict[str, dict] = field(default_factory=dict)
    pairs: dict[str, list[str]] = field(default_factory=dict)  # content -> styles
    estimate: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.problems


def _rig_key(motion) -> tuple:
    sk = motion.skeleton
    return tuple(sk.names), tuple(int(p) for p in sk.parents)


def _files(names: list[str], most: int = 3) -> str:
    shown = ", ".join(names[:most])
    return shown + (f" and {len(names) - most} more" if len(names) > most else "")


def map_rigs(library: L.Library, report: CheckReport) -> list:
    """Every row's canonical clip (``None`` where it failed); fills ``report.rigs`` and the
    problems of files that cannot be read or mapped."""
    from motion.errors import MotionError

    groups: dict[tuple, dict] = {}
    failures: dict[tuple, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    clips = []
    for row in library.rows:
        try:
            motion = L.load_motion(library.path(row))
        except (MotionError, OSError) as e:
            report.problems.append(f"{row.file}: cannot be read: {getattr(e, 'message', e)}")
            clips.append(None)
            continue
        key = _rig_key(motion)
        try:
            clip, rig = L.canonical_clip(library, row, motion)
        except MotionError as e:
            failures[key][e.message].append(row.file)
            clips.append(None)
            continue
        clips.append(clip)
        g = groups.setdefault(
            key,
            {
                "joints": motion.skeleton.num_joints,
                "files": [],
                "method": rig.method,
                "confidence": rig.confidence,
                "convention": rig.convention,
                "up": rig.up_axis,
                "height": round(float(rig.height), 3),
            },
        )
        g["files"].append(row.file)
        g["confidence"] = min(g["confidence"], rig.confidence)
    for key, messages in failures.items():
        for message, files in messages.items():
            report.problems.append(
                f"rig of {len(key[0])} joints ({_files(files)}): cannot be mapped: {message}"
            )
    report.rigs = list(groups.values())
    for g in report.rigs:
        if g["confidence"] < LOW_CONFIDENCE:
            report.warnings.append(
                f"rig of {g['joints']} joints ({_files(g['files'])}) mapped by {g['method']} "
                f"with confidence {g['confidence']:.2f}: check its mapping"
            )
    return clips


def check_styles(rows: list[L.Row], frames: dict[str, int], report: CheckReport) -> None:
    """Per style its takes, actions and held-out takes; the pairs; the style problems."""
    usable = [r for r in rows if frames.get(r.file, 0) >= WINDOW]
    short = [r.file for r in rows if r.file in frames and frames[r.file] < WINDOW]
    if short:
        report.warnings.append(
            f"{len(short)} clip(s) shorter than a training window ({WINDOW} frames at 30 "
            f"fps), not used: {_files(short, 5)}"
        )
    styles_of: dict[str, set[str]] = defaultdict(set)
    for r in usable:
        if not r.held_out:
            styles_of[r.content].add(r.style)
    report.pairs = {c: sorted(s) for c, s in sorted(styles_of.items()) if len(s) >= 2}
    takes = Counter(r.style for r in rows)
    for style in sorted(takes):
        mine = [r for r in rows if r.style == style]
        contents = sorted({r.content for r in mine})
        shared = [c for c in contents if c in report.pairs and style in report.pairs[c]]
        held = sum(r.held_out for r in mine)
        report.styles[style] = {
            "takes": len(mine),
            "held_out": held,
            "contents": contents,
            "shared_contents": shared,
        }
        if len(mine) < MIN_TAKES:
            report.problems.append(
                f"style {style} has {len(mine)} take (at least {MIN_TAKES} needed)"
            )
        elif not shared:
            report.problems.append(
                f"style {style} shares no action with another style (its actions: "
                f"{', '.join(contents)}): the paired stage has nothing to learn it from"
            )
        if not held and len(mine) >= MIN_TAKES:
            report.warnings.append(f"style {style} has no held-out take to validate it on")
    if len(takes) < 2:
        report.problems.append(f"{len(takes)} style(s): a library needs at least two")


def measure_steps_per_second(
    num_styles: int, channels: int = 128, seconds: float = 4.0
) -> dict[str, float]:
    """Training steps per second of the translator (networks, losses, the discriminator's
    step; batches of random numbers, so drawing examples is not counted) and of one fast
    network, on this machine with one torch thread."""
    import torch

    from motion import features as Fe
    from training import fast_common as FC
    from training.translator import fit
    from training.translator.networks import RESTYLER_IN, NetworkConfig, Translator

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        cfg = fit.TrainConfig(w_adv=0.1, w_track=2.0)
        net_cfg = NetworkConfig(channels=channels, num_styles=num_styles)
        trainer = fit.Trainer.__new__(fit.Trainer)
        trainer.cfg, trainer.device, trainer.step = cfg, torch.device("cpu"), 0
        trainer.net = Translator(net_cfg)
        trainer.disc = fit.Discriminator(net_cfg)
        trainer.opt = torch.optim.Adam(trainer.net.parameters())
        trainer.disc_opt = torch.optim.Adam(trainer.disc.parameters())
        trainer.fk = fit.RootLocalFK()
        out_channels = Fe.OUTPUT_CHANNELS
        trainer.norm = {"out_mean": torch.zeros(out_channels), "out_std": torch.ones(out_channels)}
        gen = torch.Generator().manual_seed(0)
        b, t, ts = cfg.batch, cfg.window, cfg.style_window
        batch = {
            "content": torch.randn(b, RESTYLER_IN, t, generator=gen),
            "content_pos": torch.randn(b, Fe.STYLE3D_CHANNELS, t, generator=gen),
            "target": torch.randn(b, out_channels, t, generator=gen),
            "style3d": torch.randn(b, Fe.STYLE3D_CHANNELS, ts, generator=gen),
            "style2d": torch.randn(b, Fe.STYLE2D_CHANNELS, ts, generator=gen),
            "real": torch.randn(b, Fe.STYLE3D_CHANNELS + 1, t, generator=gen),
            "source": torch.randint(0, 3, (b,), generator=gen),
            "labels": torch.randint(0, num_styles, (b,), generator=gen),
            "real_labels": torch.randint(0, num_styles, (b,), generator=gen),
        }
        trainer.batch = lambda: batch
        translator = _rate(trainer.train_step, seconds)

        net = FC.StyleNet()
        opt = torch.optim.Adam(net.parameters())
        x = torch.randn(16, Fe.CONTROL_CHANNELS, FC.WINDOW, generator=gen)
        y = torch.randn(16, Fe.OUTPUT_CHANNELS, FC.WINDOW, generator=gen)

        def fast_step() -> None:
            loss = (net(x) - y).abs().mean()
            opt.zero_grad()
            loss.backward()
            opt.step()

        fast = _rate(fast_step, seconds / 2)
    finally:
        torch.set_num_threads(threads)
    return {"translator": translator, "fast": fast}


def _rate(step, seconds: float) -> float:
    """Steps per second of this process's CPU time (one thread): what the machine's other
    work does not change."""
    step()  # warm-up
    n, started = 0, time.process_time()
    while time.process_time() - started < seconds or n < 3:
        step()
        n += 1
    return n / (time.process_time() - started)


def estimate_hours(
    report: CheckReport,
    rows: list[L.Row],
    translator_steps: int,
    rates: dict[str, float],
    cores: int = 2,
) -> dict:
    """CPU-hours from random weights to exported models (aligning the pairs, the
    translator's steps, the fast networks') at the measured ``rates`` (steps per CPU
    second), and the hours they take on this machine when idle (the translator on one core,
    the fast networks ``cores`` at once) and with a GPU (the translator at its recorded
    rate there, the rest as here)."""
    per_content = Counter((r.content, r.style) for r in rows if not r.held_out)
    by_content: dict[str, int] = Counter()
    for (content, _), n in per_content.items():
        by_content[content] += n
    pairs = 2 * sum(n * (n - 1) for n in by_content.values())  # with mirror images
    align_h = pairs * ALIGN_SECONDS_PER_PAIR / 3600
    styles = len(report.styles)
    translator_h = translator_steps / rates["translator"] / 3600
    fast_cpu_h = styles * FAST_STEPS / rates["fast"] / 3600
    fast_h = fast_cpu_h / max(1, min(cores, styles))
    return {
        "pairs_to_align": pairs,
        "translator_steps": translator_steps,
        "fast_steps": styles * FAST_STEPS,
        "steps_per_cpu_s": {k: round(v, 2) for k, v in rates.items()},
        "gpu_translator_steps_per_s": GPU_TRANSLATOR_STEPS_PER_S,
        "cpu_hours": round(align_h + translator_h + fast_cpu_h, 2),
        "hours_here": round(align_h + translator_h + fast_h, 2),
        "hours_gpu": round(
            align_h + translator_steps / GPU_TRANSLATOR_STEPS_PER_S / 3600 + fast_h, 2
        ),
    }


def schedule_size(schedule: Path | None = None) -> tuple[int, int]:
    """The translator's steps over every stage of ``schedule`` (the shipped one) and the
    channels its last stage trains."""
    from training.translator.fit import TrainConfig
    from training.translator.networks import NetworkConfig
    from training.translator.schedule import SCHEDULE, load_schedule

    stages = load_schedule(schedule or SCHEDULE)
    steps = sum(int(s["flags"].get("steps", TrainConfig.steps)) for s in stages)
    return steps, int(stages[-1]["flags"].get("channels", NetworkConfig().channels))


def check(root: Path, translator_steps: int | None = None, measure: bool = True) -> CheckReport:
    """The report on the library at ``root`` (module docstring); its clips are cached when
    it has no problem. The estimate is for ``translator_steps`` (the shipped schedule's
    by default)."""
    started = time.perf_counter()
    library, problems = L.read_labels(root)
    report = CheckReport(library=library.name, problems=problems)
    clips = map_rigs(library, report)
    frames = {c.extra["file"]: c.num_frames for c in clips if c is not None}
    report.clips = len(frames)
    report.frames = int(sum(frames.values()))
    check_styles([r for r in library.rows if r.file in frames], frames, report)
    report.estimate["read_seconds"] = round(time.perf_counter() - started, 1)
    if report.ok:
        L.clips_of(library, clips)
        if measure:
            steps, channels = schedule_size()
            translator_steps = translator_steps or steps
            rates = measure_steps_per_second(max(len(report.styles), 1), channels)
            report.estimate |= estimate_hours(report, library.rows, translator_steps, rates)
    return report


def render(report: CheckReport) -> str:
    """The report as text for a terminal."""
    lines = [f"library {report.library}: {report.clips} clips, {report.frames} frames at 30 fps"]
    for g in report.rigs:
        how = g["method"] + (f" ({g['convention']})" if g["convention"] else "")
        lines.append(
            f"  rig of {g['joints']} joints, {len(g['files'])} clip(s) ({_files(g['files'])}): "
            f"mapped by {how}, confidence {g['confidence']:.2f}, up {g['up']}, "
            f"height {g['height']:g} file units"
        )
    if report.styles:
        lines.append(f"styles ({len(report.styles)}):")
        for style, s in report.styles.items():
            lines.append(
                f"  {style}: {s['takes']} takes ({s['held_out']} held out), "
                f"actions {', '.join(s['contents'])}"
            )
    if report.pairs:
        count = sum(len(s) for s in report.pairs.values())
        lines.append(f"style x content pairs the paired stage can use ({count}):")
        for content, styles in report.pairs.items():
            lines.append(f"  {content}: {', '.join(styles)}")
    e = report.estimate
    if "hours_here" in e:
        rate = e["steps_per_cpu_s"]
        lines.append(
            f"estimate: {e['cpu_hours']:.2f} CPU-hours; {e['hours_here']:.2f} hours here when "
            f"idle, {e['hours_gpu']:.2f} with a GPU ({e['translator_steps']} translator "
            f"steps at {rate['translator']:.2f} per CPU-second, drawing examples not counted; "
            f"{e['fast_steps']} fast steps at {rate['fast']:.1f}; the translator at "
            f"{e['gpu_translator_steps_per_s']} steps/s on a GPU, as recorded on an H200; "
            f"{e['pairs_to_align']} pairs to align)"
        )
    for w in report.warnings:
        lines.append(f"warning: {w}")
    for p in report.problems:
        lines.append(f"problem: {p}")
    lines.append(
        f"{len(report.problems)} problem(s): not trainable until they are fixed"
        if report.problems
        else "ready to train"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``motion-style-train check``: the report; status 1 when the library has a problem."""
    import argparse
    import json
    from dataclasses import asdict

    parser = argparse.ArgumentParser(
        prog="motion-style-train check", description="check a library before training on it"
    )
    parser.add_argument("library", type=Path, help="folder of clips and labels.csv")
    parser.add_argument("--json", action="store_true", help="the report as JSON")
    parser.add_argument(
        "--no-estimate", action="store_true", help="skip measuring this machine's speed"
    )
    args = parser.parse_args(argv)
    report = check(args.library, measure=not args.no_estimate)
    if args.json:
        print(json.dumps(asdict(report) | {"ok": report.ok}, indent=1))
    else:
        print(render(report))
    return 0 if report.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())

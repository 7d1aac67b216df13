"""``motion-style-train``: a studio's library (``training.library``) to served models, in one
command.

    motion-style-train check LIB [--json] [--no-estimate]
    motion-style-train LIB -o models/NAME --licence TEXT [--device auto|cpu|cuda]
        [--work checkpoints/NAME] [--schedule training/translator/schedule.json]
        [--fast-steps 5000] [--jobs 2] [--runs runs/NAME]

``check`` (``training.library_check``) reads the library, maps every rig, lists the pairs,
names every problem and estimates the hours; it exits 1 when the library cannot be trained
on. Training checks first (and stops on a problem before training anything), then:

1. the translator, every stage of the schedule (``training.translator.fit``, the shipped
   Bandai model's schedule by default) on the library's pairs, from random weights;
2. its export into ``-o`` (``model_export.translator``: ONNX, statistics, style table,
   the manifest entry ``translator-NAME``);
3. one fast network per style distilled from that translator on the library's clips
   (``training.fast_style``, ``--jobs`` at once) and their export (``fast-NAME``).

Both entries record the library's name, its content hash (``training.library``), the
licence given (required: the user's statement of their rights to the data), the schedule
and the figures measured (validation losses on the held-out takes, how often a take's code
is nearest its style's, the fast networks' fit). Checkpoints live in ``--work``; run again,
the command continues where it stopped: a stage from its last checkpoint (weights, optimiser
and random state), finished stages and styles skipped. Progress bars give an ETA;
TensorBoard logs go to ``--runs``. ``--device auto`` takes CUDA where torch sees it.
Under ``torchrun --nproc_per_node N -m model_export.train_library ...`` both families
train on N processes (``training.distributed``: gloo on CPUs, NCCL on GPUs): the
translator, then each fast network in turn; the first process exports, the others wait.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def parse_args(argv: list[str]) -> argparse.Namespace:
    from training.fast_style import parse_args as fast_args
    from training.translator.schedule import SCHEDULE

    p = argparse.ArgumentParser(
        prog="motion-style-train", description="train both style families on a library"
    )
    p.add_argument("library", type=Path, help="folder of clips and labels.csv")
    p.add_argument("-o", "--out", type=Path, required=True, help="models folder to write")
    p.add_argument("--licence", required=True, help="the licence the models are under")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto")
    p.add_argument("--work", type=Path, help="checkpoints (default checkpoints/<NAME>)")
    p.add_argument("--schedule", type=Path, default=SCHEDULE, help="the translator's stages")
    p.add_argument(
        "--fast-steps", type=int, default=fast_args(["--all"]).steps, help="steps per style"
    )
    p.add_argument("--jobs", type=int, default=2, help="fast networks trained at once")
    p.add_argument("--threads", type=int, default=1, help="torch threads per process")
    p.add_argument("--runs", type=Path, help="TensorBoard logs (default runs/<NAME>)")
    args = p.parse_args(argv)
    args.name = args.out.resolve().name
    args.work = args.work or REPO / "checkpoints" / args.name
    args.runs = args.runs or REPO / "runs" / args.name
    return args


def device_of(choice: str) -> str:
    import torch

    if choice == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if choice == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: torch sees no CUDA device here")
    return choice


def translator_flags(stage: dict, checkpoint: Path, finished: list[str]) -> list[str]:
    """``fit`` flags that run ``stage``: from its own last checkpoint where it was under
    way (``--resume``: with the optimiser and random state where ``<checkpoint>.state``
    is there, else the weights and step alone), else from the previous stage's weights
    (``--init``), else from random weights."""
    import torch

    from training.translator.schedule import stage_argv

    flags = ["--out", str(checkpoint), "--stage", stage["name"], *stage_argv(stage)]
    if checkpoint.exists():
        payload = torch.load(checkpoint, map_location="cpu", weights_only=False)
        if payload.get("stage") == stage["name"] and stage["name"] not in finished:
            return [*flags, "--resume"]
        if finished:
            return [*flags, "--init", str(checkpoint)]
    return flags


def train_translator(args, device: str) -> Path:
    from training.translator import fit
    from training.translator.schedule import finished_stages, load_schedule

    checkpoint = args.work / "translator.pt"
    stages = load_schedule(args.schedule)
    done = finished_stages(checkpoint)
    if done != [s["name"] for s in stages][: len(done)]:
        raise SystemExit(f"{checkpoint} finished stages {done}, not a prefix of {args.schedule}")
    for stage in stages[len(done) :]:
        flags = translator_flags(stage, checkpoint, done)
        flags += ["--library", str(args.library), "--device", device]
        flags += ["--threads", str(args.threads)]
        flags += ["--log", str(args.runs / "translator" / stage["name"])]
        print(f"translator, stage {stage['name']}: {' '.join(flags)}", flush=True)
        fit.main(flags)
        done = finished_stages(checkpoint)
        if stage["name"] not in done:
            raise SystemExit(f"stage {stage['name']} did not finish")
    return checkpoint


def provenance(args, library_hash: str) -> tuple[list[str], dict]:
    """The entries' training data line and the ``extra`` both carry."""
    from training.translator.schedule import load_schedule

    schedule = load_schedule(args.schedule)
    data = [f"library {args.name} (sha256 {library_hash}), licence as declared: {args.licence}"]
    extra = {
        "library": args.name,
        "library_sha256": library_hash,
        "schedule": schedule,
        "fast_steps": args.fast_steps,
    }
    return data, extra


def train_fast(args, styles: list[str], device: str) -> Path:
    from training import distributed, fast_style

    ckpt_dir = args.work / "fast"
    todo = [s for s in styles if not (ckpt_dir / f"style_{s}.pt").exists()]
    todo = distributed.gather(todo)[0]  # the first process's view, everywhere
    if todo:
        flags = [f"--style={s}" for s in todo]
        flags += ["--steps", str(args.fast_steps), "--jobs", str(args.jobs)]
        flags += ["--threads", str(args.threads), "--checkpoint-dir", str(ckpt_dir)]
        flags += ["--log-dir", str(args.runs / "fast"), "--device", device]
        flags += ["--models-dir", str(args.out), "--library", str(args.library)]
        if distributed.rank() == 0:
            print(f"fast networks: {len(todo)} of {len(styles)} styles to train", flush=True)
        fast_style.main(flags)
    return ckpt_dir


def train_main(argv: list[str]) -> int:
    import torch

    from training import distributed, library_check
    from training import library as L

    args = parse_args(argv)
    report = library_check.check(args.library, measure=False)
    if not report.ok:
        print(library_check.render(report))
        return 1
    device = distributed.start(device_of(args.device))
    torch.set_num_threads(args.threads)
    library, _ = L.read_labels(args.library)
    data, extra = provenance(args, library.content_hash())
    checkpoint = train_translator(args, device)
    translator = (
        export_translator(args, checkpoint, data, extra) if distributed.rank() == 0 else None
    )
    translator = distributed.gather(translator)[0]  # the others wait for the export
    styles = list(translator["extra"]["styles"])
    ckpt_dir = train_fast(args, styles, device)
    if distributed.rank() > 0:
        distributed.stop()
        return 0
    from model_export import fast as export_fast

    fast = export_fast.export(
        ckpt_dir,
        args.out,
        name=f"fast-{args.name}",
        training_data=data,
        licence=args.licence,
        only=styles,
        smoothing=translator["extra"]["output_smoothing"],
        extra=extra,
        strengths={},
    )
    summary = {
        "models": str(args.out),
        "translator": translator["version"],
        "fast": fast["version"],
        "styles": styles,
        "validation": translator["metrics"].get("validation", {}),
    }
    print(json.dumps(summary, indent=1))
    distributed.stop()
    return 0


def export_translator(args, checkpoint: Path, data: list[str], extra: dict) -> dict:
    """The translator's manifest entry, its ONNX and tables written into ``args.out``."""
    from model_export import translator as export
    from training import library as L

    args.out.mkdir(parents=True, exist_ok=True)
    return export.export(
        checkpoint,
        args.out,
        L.read_library(args.library),
        name=f"translator-{args.name}",
        training_data=data,
        licence=args.licence,
        extra=extra,
        measure_smoothing=False,
        gains={},  # Bandai's own were chosen on Bandai's evaluation
    )


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["check"]:
        from training.library_check import main as check_main

        return check_main(argv[1:])
    return train_main(argv)


if __name__ == "__main__":
    raise SystemExit(main())

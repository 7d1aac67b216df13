"""Replay the shipped dance model's training schedule (``dance_schedule.json`` beside this file).

    python -m training.dance_schedule [--out checkpoints/dance.pt] [--from-scratch]

Each stage is the flags of one ``python -m training.dance`` run (the others at their
defaults); a stage after the first starts (``--init``) from the weights, statistics and start
poses the previous one ended with. The checkpoint records the stages it finished, so the
replay continues an unfinished stage (``--resume``) or starts the next one, and does nothing
when every stage is done; ``--from-scratch`` runs every stage again.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from training import dance as TD


def load_schedule(path: Path = TD.SCHEDULE) -> list[dict]:
    return json.loads(path.read_text())["stages"]


def stage_argv(stage: dict) -> list[str]:
    """``training.dance`` flags of a stage: ``{"flag": value}`` -> ``--flag value``, and a
    true boolean -> ``--flag``."""
    argv = []
    for name, value in stage["flags"].items():
        if value is True:
            argv.append(f"--{name}")
        elif value is not False:
            argv += [f"--{name}", str(value)]
    return argv


def progress(checkpoint: Path) -> tuple[list[str], str | None]:
    """The stages ``checkpoint`` finished, and the stage it is part-way through (or None)."""
    if not checkpoint.exists():
        return [], None
    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=False)
    done = list(ckpt.get("stages", []))
    current = ckpt.get("train_config", {}).get("stage")
    return done, (current if current and current not in done else None)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=TD.CHECKPOINT)
    parser.add_argument("--from-scratch", action="store_true")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    stages = load_schedule()
    names = [s["name"] for s in stages]
    done, current = ([], None) if args.from_scratch else progress(args.out)
    if args.out.exists() and not args.from_scratch and not done and current is None:
        current = names[0]  # saved before checkpoints recorded stages: the first one's
    if done != names[: len(done)]:
        raise SystemExit(f"{args.out} finished stages {done}, not a prefix of the schedule")
    for stage in stages[len(done) :]:
        flags = ["--checkpoint", str(args.out), "--threads", str(args.threads)]
        flags += ["--stage", stage["name"]]
        if stage["name"] == current:
            flags.append("--resume")
        elif done:
            flags += ["--init", str(args.out)]
        print(f"stage {stage['name']}: {stage_argv(stage)}", flush=True)
        TD.main(flags + stage_argv(stage))
        done, current = progress(args.out)
        if stage["name"] not in done:
            raise SystemExit(f"stage {stage['name']} stopped before its last step; run again")
    print(f"{args.out}: every stage of the schedule done ({', '.join(done)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

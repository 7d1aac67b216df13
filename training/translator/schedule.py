"""Replay the shipped translator's training schedule (``schedule.json`` beside this file).

    python -m training.translator.schedule [--out checkpoints/translator.pt] [--from-scratch]

The schedule is a list of stages, each the flags of one ``training.translator.fit`` run;
a stage starts from the weights the previous one ended with. The checkpoint records the
stages it finished (``stages`` in its payload), so by default the replay continues from
the last stage the checkpoint at ``--out`` finished, and does nothing when it finished
all of them; ``--from-scratch`` runs every stage from random weights. Flags the schedule
does not give take ``TrainConfig``'s defaults: nothing is carried over from a
checkpoint's saved configuration.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from training.translator import fit

SCHEDULE = Path(__file__).with_name("schedule.json")


def load_schedule(path: Path = SCHEDULE) -> list[dict]:
    return json.loads(path.read_text())["stages"]


def stage_argv(stage: dict) -> list[str]:
    """``fit`` command-line flags of a stage (``{"flag": value}`` -> ``--flag value``)."""
    argv = []
    for name, value in stage["flags"].items():
        argv += [f"--{name}", str(value)]
    return argv


def finished_stages(checkpoint: Path) -> list[str]:
    if not checkpoint.exists():
        return []
    return list(torch.load(checkpoint, map_location="cpu", weights_only=False).get("stages", []))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=fit.REPO / "checkpoints" / "translator.pt")
    parser.add_argument("--from-scratch", action="store_true")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    stages = load_schedule()
    done = [] if args.from_scratch else finished_stages(args.out)
    if done != [s["name"] for s in stages][: len(done)]:
        raise SystemExit(f"{args.out} finished stages {done}, not a prefix of the schedule")
    for stage in stages[len(done) :]:
        flags = ["--out", str(args.out), "--threads", str(args.threads), "--stage", stage["name"]]
        if done:
            flags += ["--init", str(args.out)]
        print(f"stage {stage['name']}: {stage_argv(stage)}", flush=True)
        fit.main(flags + stage_argv(stage))
        done.append(stage["name"])
    print(f"{args.out}: every stage of the schedule done ({', '.join(done)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

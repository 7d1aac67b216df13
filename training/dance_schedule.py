"""Replay the shipped dance model's training schedule (``dance_schedule.json`` beside this file).

    python -m training.dance_schedule [--out checkpoints/dance.pt] [--from-scratch] [--fold K]
        [--device cuda --prepared cache/carry/dance_prepared.npz]

A stage is either the flags of one ``python -m training.dance`` run (the others at their
defaults), started (``--init``) from the weights, statistics and start poses of the stage
named by its ``from`` (by default the one before it), or a ``blend``: the weights of its
``from`` stage moved ``weight`` of the way to the mean of its ``tuned`` stages' (WiSE-FT,
Wortsman et al. 2022, over a model soup of fine-tunings from one start). Each stage ends
in ``--work``/NAME.pt, so a replay continues an unfinished stage (``--resume``), skips the
finished ones, and copies the last stage's checkpoint to ``--out``; it does nothing when
``--out`` has every stage; ``--from-scratch`` runs every stage again. ``--fold K`` trains
every stage without fold K's songs (``training.dance.FOLDS``; the shipped model is fold 0's).
``--device`` and ``--prepared`` pass to every stage: on a lent machine, which has no data
folder, the sequences come from the file ``python -m training.carry dance`` wrote.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shutil
from pathlib import Path

import torch

from training import dance as TD

WORK = TD.CHECKPOINT.parent / "dance-stages"


def load_schedule(path: Path = TD.SCHEDULE) -> list[dict]:
    return json.loads(path.read_text())["stages"]


def stage_argv(stage: dict) -> list[str]:
    """``training.dance`` flags of a stage: ``{"flag": value}`` -> ``--flag value``, and a
    true boolean -> ``--flag``."""
    argv = []
    for name, value in stage.get("flags", {}).items():
        if value is True:
            argv.append(f"--{name}")
        elif value is not False:
            argv += [f"--{name}", str(value)]
    return argv


def stages_of(checkpoint: Path, fold: int = 0) -> tuple[list[str], str | None]:
    """The stages ``checkpoint`` finished, and the stage it is part-way through (or None);
    ``SystemExit`` when it is another fold's than ``fold`` (it has seen that fold's songs)."""
    if not checkpoint.exists():
        return [], None
    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=False)
    TD.require_fold(ckpt, fold, checkpoint)
    done = list(ckpt.get("stages", []))
    current = ckpt.get("train_config", {}).get("stage")
    return done, (current if current and current not in done else None)


def blend(start: dict, tuned: list[dict], weight: float) -> dict:
    """A checkpoint whose weights are ``(1 - weight)`` of ``start``'s plus ``weight`` of the
    mean of ``tuned``'s (fine-tuned from ``start``: layers it lacks, as FiLM's zero start,
    count as zero), with the first tuned one's configuration, statistics and start poses."""
    mean = {k: sum(t["model"][k] for t in tuned) / len(tuned) for k in tuned[0]["model"]}
    weights = {k: (1.0 - weight) * start["model"].get(k, torch.zeros_like(v)) + weight * v
               for k, v in mean.items()}  # fmt: skip
    out = {k: v for k, v in tuned[0].items() if k != "model"}
    out["model"] = weights
    out["step"] = int(start["step"]) + sum(int(t["step"]) for t in tuned)  # in all
    out["best_val"] = None
    return out


def run_blend(stage: dict, work: Path, names: list[str]) -> None:
    spec = stage["blend"]
    load = lambda name: torch.load(work / f"{name}.pt", map_location="cpu", weights_only=False)  # noqa: E731
    start, tuned = load(spec["from"]), [load(n) for n in spec["tuned"]]
    folds = {TD.fold_of(c) for c in [start, *tuned]}
    if len(folds) != 1:
        raise SystemExit(f"stage {stage['name']} would blend folds {sorted(folds)}")
    out = blend(start, tuned, float(spec["weight"]))
    done = set(start.get("stages", [])) | {s for t in tuned for s in t.get("stages", [])}
    out["stages"] = [n for n in names if n in done] + [stage["name"]]
    out["stage_steps"] = {spec["from"]: int(start["step"]),
                          **{n: int(t["step"]) for n, t in zip(spec["tuned"], tuned, strict=True)}}  # fmt: skip
    out["train_config"] = {"stage": stage["name"], **spec, "fold": folds.pop()}
    out["saved_at"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    tmp = work / f"{stage['name']}.tmp"
    torch.save(out, tmp)
    os.replace(tmp, work / f"{stage['name']}.pt")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=TD.CHECKPOINT)
    parser.add_argument("--work", type=Path, default=WORK, help="each stage's checkpoint")
    parser.add_argument("--schedule", type=Path, default=TD.SCHEDULE)
    parser.add_argument("--from-scratch", action="store_true")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--fold", type=int, default=0, choices=range(len(TD.FOLDS)))
    parser.add_argument("--device", default="cpu", help="torch device to train on (cuda, ...)")
    parser.add_argument("--prepared", type=Path, default=None,
                        help="the sequences from this file, not from the data folder")  # fmt: skip
    args = parser.parse_args(argv)
    stages = load_schedule(args.schedule)
    names = [s["name"] for s in stages]
    if not args.from_scratch and stages_of(args.out, args.fold)[0] == names:
        print(f"{args.out}: every stage of the schedule done ({', '.join(names)})")
        return 0
    args.work.mkdir(parents=True, exist_ok=True)
    for i, stage in enumerate(stages):
        name, path = stage["name"], args.work / f"{stage['name']}.pt"
        done, current = ([], None) if args.from_scratch else stages_of(path, args.fold)
        if name in done:
            print(f"stage {name}: done ({path})", flush=True)
            continue
        if "blend" in stage:
            print(f"stage {name}: blend {stage['blend']}", flush=True)
            run_blend(stage, args.work, names)
            continue
        flags = ["--checkpoint", str(path), "--threads", str(args.threads), "--stage", name,
                 "--fold", str(args.fold), "--device", args.device]  # fmt: skip
        if args.prepared:
            flags += ["--prepared", str(args.prepared)]
        if current == name:
            flags.append("--resume")
        elif i > 0:
            flags += ["--init", str(args.work / f"{stage.get('from', names[i - 1])}.pt")]
        print(f"stage {name}: {stage_argv(stage)}", flush=True)
        TD.main(flags + stage_argv(stage))
        if name not in stages_of(path, args.fold)[0]:
            raise SystemExit(f"stage {name} stopped before its last step; run again")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(args.work / f"{names[-1]}.pt", args.out)
    print(f"{args.out}: every stage of the schedule done ({', '.join(names)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

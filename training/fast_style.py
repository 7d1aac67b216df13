"""Train the fast style networks, one per style, by distillation from the shipped
translator.

    python -m training.fast_style --all [--jobs 2] [--steps N]
    python -m training.fast_style --style angry
    torchrun --nproc_per_node 2 -m training.fast_style --all

Each style's network (``training.fast_common.StyleNet``) learns what the translator's
restyler does for that style's named code: from the same input (the content's head, hands,
feet and travel about its own mean posture) to the same output (every joint's rotation and
the hips' height): L1 on the standardised channels, away from a window's ends. The engine
then finishes it as the translator finishes its own output. The content is every Bandai
take and the first ``DANCE_SECONDS`` of each Dance with Melody take, mirrored, and turning
(:func:`content_motions`); a style's targets are made in its own process (a minute: the
translator on every clip once).

Why not holden2017's positions, projection and IK fit: docs/translator.md.

Under ``torchrun`` (``training.distributed``) the processes train one style at a time
together: each makes the targets of its own share of the content and draws its batches
there (as ``DistributedSampler`` shares a data set), the batch split between them so that
N processes take the steps of one with the same total batch; their gradients are averaged
after each backward pass. Without it, ``--jobs`` trains that many styles at once instead.

Writes ``checkpoints/fast/style_<name>.pt`` (weights only) and logs to
``runs/fast/style_<name>``. ``MOTION_SMOKE=1`` runs a few steps on four takes.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motion import canonical as C
from motion import features as Fe
from training import distributed
from training import fast_common as FC

DANCE_SECONDS = 60  # of each Dance with Melody take, in the content
TURN_RATE = 3.0  # rad/s, standard deviation of the turning variants' rates
VARIANT_SEED = 1
EDGE = 20  # frames at each end of a training window left out of the loss (no context there)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--style", action="append", help="style name (repeatable)")
    who.add_argument("--all", action="store_true", help="every style of the shipped translator")
    p.add_argument("--steps", type=int, default=5000, help="steps per style")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many (smoke)")
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--window", type=int, default=FC.WINDOW)
    p.add_argument("--hidden", type=int, default=FC.STYLE_HIDDEN)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--checkpoint-dir", default=str(FC.CHECKPOINTS))
    p.add_argument("--log-dir", default=str(FC.RUNS), help="TensorBoard and text logs")
    p.add_argument("--threads", type=int, default=None, help="torch threads per process")
    p.add_argument("--jobs", type=int, default=1, help="styles trained at once, one process each")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    p.add_argument(
        "--models-dir", type=Path, help="the teacher translator's models folder (the shipped)"
    )
    p.add_argument(
        "--library", type=Path, help="content from this library (training.library) alone"
    )
    return p.parse_args(argv)


def teacher_clips(library: Path | None = None) -> list:
    """The content: every Bandai take, and the first ``DANCE_SECONDS`` of each Dance with
    Melody take (canonical clips); four takes under ``MOTION_SMOKE``. With ``library``,
    that library's clips (``training.library``) instead."""
    from training import data as D

    if library is not None:
        from training.library import read_library

        clips = read_library(library)
        return clips[:4] if FC.smoke() else clips
    if FC.smoke():
        return D.load_bandai()[:4]
    frames = int(DANCE_SECONDS * Fe.FPS)
    dances = [
        D.clip_from_motion(c.motion.slice(0, frames), name=c.name, dataset=c.dataset, take=c.take)
        for c in D.load_dance_with_melody()
    ]
    return D.load_bandai() + dances


def content_motions(library: Path | None = None) -> list:
    """The canonical motions a style's targets are made from: :func:`teacher_clips`'s, each
    also mirrored, and each of those once more turning (``TURN_RATE``) and facing off its
    path (any way) at random: foreign clips turn and step sideways far more than Bandai's
    takes, and a network trained on those alone followed the translator less well there."""
    motions = [c.motion for c in teacher_clips(library)]
    motions += [C.mirrored(m) for m in motions]
    rng = np.random.default_rng(VARIANT_SEED)
    rates = rng.normal(0.0, TURN_RATE, len(motions))
    facings = rng.uniform(-np.pi, np.pi, len(motions))
    return motions + [
        C.turned(m, rate, facing) for m, rate, facing in zip(motions, rates, facings, strict=True)
    ]


def style_names(models_dir: Path | None = None) -> list[str]:
    """The teacher translator's styles (the shipped one's, or that in ``models_dir``)."""
    from training.judges import load_engine

    return list(load_engine("translator", models_dir)[0].style_names)


def targets(
    style: str, models_dir: Path | None = None, library: Path | None = None
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per content clip, the restyler's input ``(F, CONTROL_CHANNELS)`` and the teacher
    translator's output for ``style``'s named code ``(F, OUTPUT_CHANNELS)``, standardised:
    the shipped translator on :func:`content_motions`, or that in ``models_dir`` on
    ``library``'s. Under ``torchrun``, this process's share of the clips alone."""
    from training.judges import load_engine

    engine = load_engine("translator", models_dir)[0]
    code = engine.code_of_name(style).code
    share = content_motions(library)[distributed.rank() :: distributed.world()]
    controls = [engine.restyler_input(m) for m in share]
    return controls, [engine.restyled(x, code) for x in controls]


class StyleTrainer:
    """One style's network fitted to the translator's outputs."""

    def __init__(self, style: str, control: list[np.ndarray], output: list[np.ndarray], args):
        self.style, self.control, self.output, self.args = style, control, output, args
        sizes = np.array([len(x) for x in control], dtype=np.float64)
        self.weights = sizes / sizes.sum()

    def batch(self, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """Windows ``(batch, channels, window)``, clips drawn in proportion to their frames,
        shorter ones padded with their first and last frames; this process's part of the
        batch under ``torchrun``."""
        xs, ys, length = [], [], self.args.window
        size = -(-self.args.batch // distributed.world())
        for k in rng.choice(len(self.control), size=size, p=self.weights):
            x, y = self.control[k], self.output[k]
            pad = max(0, length - len(x))
            if pad:
                x = np.pad(x, ((0, pad), (0, 0)), mode="edge")
                y = np.pad(y, ((0, pad), (0, 0)), mode="edge")
            start = int(rng.integers(0, len(x) - length + 1))
            xs.append(x[start : start + length].T)
            ys.append(y[start : start + length].T)
        return torch.tensor(np.stack(xs)), torch.tensor(np.stack(ys))

    def train(self, log: FC.Logger | None) -> tuple[FC.StyleNet, dict]:
        args, rank = self.args, distributed.rank()
        torch.manual_seed(args.seed)
        rng = np.random.default_rng([args.seed, rank] if rank else args.seed)
        net = FC.StyleNet(hidden=args.hidden).to(args.device)
        distributed.broadcast_parameters(net)
        opt = torch.optim.Adam(net.parameters(), lr=args.lr)
        steps = min(args.steps, args.max_steps or args.steps)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps, eta_min=args.lr * 0.1)
        started, avg, step = time.time(), None, 0
        progress = tqdm(range(1, steps + 1), desc=f"style {self.style}", mininterval=10,
                        disable=rank > 0)  # fmt: skip
        for step in progress:
            x, y = (t.to(args.device) for t in self.batch(rng))
            loss = (net(x) - y)[..., EDGE:-EDGE].abs().mean()
            opt.zero_grad()
            loss.backward()
            distributed.average_gradients(net.parameters())
            opt.step()
            sched.step()
            avg = loss.item() if avg is None else 0.98 * avg + 0.02 * loss.item()
            if step % 20 == 0 and log is not None:
                log.scalars(step, {"train/l1": avg})
        spread = distributed.spread(net)
        if spread > 0:
            raise RuntimeError(f"the processes' weights drifted apart ({spread:.2e})")
        result = {
            "steps": step,
            "minutes": round((time.time() - started) / 60, 2),
            "train_l1": round(avg, 6),
            "processes": distributed.world(),
        }
        return net.cpu(), result


def train_style(name: str, args: argparse.Namespace) -> dict:
    """One style's network trained on :func:`targets` and saved to
    ``<checkpoint-dir>/style_<name>.pt``."""
    if args.threads:
        torch.set_num_threads(args.threads)
    control, output = targets(name, args.models_dir, args.library)
    first = distributed.rank() == 0
    log = FC.Logger(f"style_{name}", Path(args.log_dir)) if first else None
    net, result = StyleTrainer(name, control, output, args).train(log)
    if not first:
        distributed.barrier()  # the first process's file is written before anyone goes on
        return result
    log.close()
    result["trained_at"] = dt.date.today().isoformat()
    ckpt_dir = Path(args.checkpoint_dir)
    ckpt_dir.mkdir(parents=True, exist_ok=True)
    path = ckpt_dir / f"style_{name}.pt"
    # whole or absent: the one command skips the styles whose file exists
    torch.save(
        {
            "model": net.state_dict(),
            "config": {"hidden": args.hidden, "style": name},
            "result": result,
        },
        f"{path}.tmp",
    )
    os.replace(f"{path}.tmp", path)
    distributed.barrier()
    print(f"style {name}: {json.dumps(result)}", flush=True)
    return result


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    if FC.smoke():
        args.max_steps = args.max_steps or 3
    names = style_names(args.models_dir) if args.all else args.style
    owns_group = not distributed.started()
    args.device = distributed.start(args.device)
    if distributed.world() > 1 or args.jobs == 1:
        results = {name: train_style(name, args) for name in names}
        if owns_group:
            distributed.stop()
        return results
    # one style per process, each seeded as alone (the same networks as one after another);
    # spawned, as torch's thread pools do not survive a fork
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.jobs, mp_context=context) as pool:
        results = pool.map(train_style, names, [args] * len(names))
        return dict(zip(names, results, strict=True))


if __name__ == "__main__":
    main()

"""Train the fast style networks (holden2017's feed-forward transformation networks, one
per style) by distillation from the shipped translator.

    python -m training.fast_style --all [--jobs 2] [--steps N] [--minutes-per-style M]
    python -m training.fast_style --style angry

The paper's loss (content and Gram-matrix style terms on the loss network's hidden units)
barely moved its input: on clips from outside Bandai the requested style was recognised
about as often as chance. Here each style's network learns to do what the translator does
for that style: its targets are the translator's outputs (strength 1, feet cleaned up, no
time warp; ``targets``) for Bandai takes and Dance with Melody, and for each of those
restyled once more by the translator (other manners than Bandai's actors'), and the loss
compares the projected output's joint positions with the target's (relative squared error,
as the engine decodes only the positions) and keeps bone lengths (paper eq. 8).

Needs the loss network (``python -m training.fast_autoencoder``: ``checkpoints/fast/``)
for the projection and the feature statistics. Writes ``checkpoints/fast/style_<name>.pt``
and logs to ``runs/fast/style_<name>``. ``MOTION_SMOKE=1`` runs a few steps.
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motion import contacts as CT
from motion import fast_features as FF
from motion import ik
from training import fast_common as FC

WEIGHTS = {"pos": 1.0, "bone": 100.0}
DANCE_SECONDS = 60  # of each Dance with Melody take, in the targets
RESTYLE_SEED = 1  # draws the style each content clip is also restyled to, in the targets


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--style", action="append", help="style name (repeatable)")
    who.add_argument("--all", action="store_true", help="every style of the shipped translator")
    p.add_argument("--steps", type=int, default=1000, help="steps per style")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many (smoke)")
    p.add_argument("--minutes-per-style", type=float, default=None)
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--window", type=int, default=FC.WINDOW)
    p.add_argument("--hidden", type=int, default=FC.STYLE_HIDDEN)
    p.add_argument("--lr", type=float, default=1e-3)
    for name, value in WEIGHTS.items():
        p.add_argument(f"--w-{name}", type=float, default=value, help=f"{name} loss weight")
    p.add_argument("--checkpoint-dir", default=str(FC.CHECKPOINTS))
    p.add_argument("--log-dir", default=str(FC.RUNS), help="TensorBoard and text logs")
    p.add_argument("--threads", type=int, default=None, help="torch threads per process")
    p.add_argument("--jobs", type=int, default=1, help="styles trained at once, one process each")
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args(argv)


def load_autoencoder(path) -> FC.Autoencoder:
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    ae = FC.Autoencoder(hidden=ckpt["config"]["hidden"], width=ckpt["config"]["width"])
    ae.load_state_dict(ckpt["model"])
    ae.eval()
    for p in ae.parameters():
        p.requires_grad_(False)
    return ae


# --------------------------------------------------------------------------- targets


def teacher_clips() -> list:
    """The content the targets are made of: every Bandai take, and the first
    ``DANCE_SECONDS`` of each Dance with Melody take (canonical clips); four takes under
    ``MOTION_SMOKE``."""
    from training import data as D

    if FC.smoke():
        return D.load_bandai()[:4]
    dances = D.load_dance_with_melody()
    frames = int(DANCE_SECONDS * FF.FPS)
    dances = [D.clip_from_motion(c.motion.slice(0, frames), name=c.name, dataset=c.dataset,
                                 take=c.take) for c in dances]  # fmt: skip
    return D.load_bandai() + dances


def targets(
    styles: list[str] | None = None,
) -> tuple[list[np.ndarray], dict[str, list[np.ndarray]]]:
    """Fast features of the content clips ``(F, CHANNELS)`` and, per style, of the shipped
    translator's outputs for them, frame for frame. The content is :func:`teacher_clips`,
    then each of them restyled by the translator to one style drawn at random
    (``RESTYLE_SEED``): other performers' manners than Bandai's actors', for networks that
    have to restyle clips of performers they never saw. Cached in ``cache/`` under the
    translator's version and the foot clean-up's code."""
    from training import data as D
    from training.judges import load_engine

    engine, entry, _ = load_engine("translator")
    names = styles or list(engine.style_names)
    smoke = "_smoke" if FC.smoke() else ""
    # the targets are cleaned up feet too: a change to the clean-up makes new ones
    cleanup = hashlib.sha256(b"".join(Path(m.__file__).read_bytes() for m in (ik, CT)))
    tag = f"{entry.version}_{cleanup.hexdigest()[:8]}_restyled{RESTYLE_SEED}{smoke}"
    path = D.cache_dir() / f"fast_targets_{tag}.npz"
    if path.exists():
        with np.load(path) as z:
            bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
            split = [(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
            if set(names) <= set(json.loads(str(z["styles"]))):
                # each array read once (z[key] decompresses it again), then cut per clip
                arrays = {key: z[key] for key in ("content", *(f"style_{s}" for s in names))}
                content = [arrays["content"][a:b] for a, b in split]
                return content, {s: [arrays[f"style_{s}"][a:b] for a, b in split] for s in names}
    clips = [c.motion for c in teacher_clips()]
    every = list(engine.style_names)
    rng = np.random.default_rng(RESTYLE_SEED)
    restyled = [
        engine.transfer(
            m, engine.code_of_name(every[int(rng.integers(len(every)))]).code, time_warp=False
        ).motion
        for m in tqdm(clips, desc="restyled content", mininterval=10)
    ]
    content_clips = clips + restyled
    content = [FF.encode(m).features for m in content_clips]
    out: dict[str, list[np.ndarray]] = {}
    for style in tqdm(every, desc="translator targets", mininterval=10):
        code = engine.code_of_name(style).code
        out[style] = [
            FF.encode(engine.transfer(m, code, time_warp=False).motion).features
            for m in content_clips
        ]
    tmp = str(path) + ".tmp.npz"
    np.savez_compressed(
        tmp,
        styles=np.array(json.dumps(list(out))),
        lengths=np.array([len(x) for x in content]),
        content=np.concatenate(content),
        **{f"style_{s}": np.concatenate(v) for s, v in out.items()},
    )
    os.replace(tmp, path)
    return content, {s: out[s] for s in names}


# --------------------------------------------------------------------------- training


class StyleTrainer:
    """One style's network fitted to the translator's outputs."""

    def __init__(self, style, content, target, ae, stats, args):
        self.style, self.ae, self.stats, self.args = style, ae, stats, args
        self.content = [stats.normalize(x) for x in content]
        self.target = [stats.normalize(y) for y in target]
        self.physics = FC.Physics(stats.mean, stats.std)
        sizes = np.array([len(x) for x in content], dtype=np.float64)
        self.weights = sizes / sizes.sum()

    def batch(self, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        xs, ys = [], []
        length = self.args.window
        for k in rng.choice(len(self.content), size=self.args.batch, p=self.weights):
            x, y = self.content[k], self.target[k]
            pad = max(0, length - len(x))
            if pad:
                x = np.pad(x, ((0, pad), (0, 0)), mode="edge")
                y = np.pad(y, ((0, pad), (0, 0)), mode="edge")
            start = int(rng.integers(0, len(x) - length + 1))
            xs.append(x[start : start + length])
            ys.append(y[start : start + length])
        return torch.tensor(np.stack(xs)), torch.tensor(np.stack(ys))

    def losses(self, net, x: torch.Tensor, y: torch.Tensor) -> dict[str, torch.Tensor]:
        out = self.ae(net(x))  # as the engine runs it: network, then projection
        pos = slice(0, FF.POSITION_CHANNELS)
        error = ((out[..., pos] - y[..., pos]) ** 2).mean()
        return {
            "pos": error / ((x[..., pos] - y[..., pos]) ** 2).mean().clamp_min(1e-6),
            "bone": self.physics.bone_loss(self.physics.raw(out)),
        }

    def train(self, log: FC.Logger) -> tuple[FC.StyleNet, dict]:
        args = self.args
        torch.manual_seed(args.seed)
        rng = np.random.default_rng(args.seed)
        net = FC.StyleNet(hidden=args.hidden)
        opt = torch.optim.Adam(net.parameters(), lr=args.lr)
        steps = min(args.steps, args.max_steps or args.steps)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps, eta_min=args.lr * 0.1)
        started = time.time()
        avg: dict[str, float] = {}
        step = 0
        for step in tqdm(range(1, steps + 1), desc=f"style {self.style}", mininterval=10):
            parts = self.losses(net, *self.batch(rng))
            loss = sum(getattr(args, f"w_{k}") * v for k, v in parts.items())
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            for k, v in {**parts, "total": loss}.items():
                avg[k] = v.item() if k not in avg else 0.95 * avg[k] + 0.05 * v.item()
            if step % 20 == 0:
                log.scalars(step, {f"train/{k}": v for k, v in avg.items()})
            if args.minutes_per_style and (time.time() - started) / 60 > args.minutes_per_style:
                break
        result = {
            "steps": step,
            "minutes": round((time.time() - started) / 60, 2),
            "train": {k: round(v, 6) for k, v in avg.items()},
        }
        return net, result


def train_style(
    name: str, args: argparse.Namespace, content: list[np.ndarray], target: list[np.ndarray]
) -> dict:
    """One style's network trained on :func:`targets`' ``content`` and its ``target`` and
    saved to ``<checkpoint-dir>/style_<name>.pt``."""
    if args.threads:
        torch.set_num_threads(args.threads)
    ckpt_dir = Path(args.checkpoint_dir)
    ae = load_autoencoder(ckpt_dir / "autoencoder.pt")
    stats = FF.FastStats.load(ckpt_dir / "stats.npz")
    log = FC.Logger(f"style_{name}", Path(args.log_dir))
    net, result = StyleTrainer(name, content, target, ae, stats, args).train(log)
    log.close()
    result["trained_at"] = dt.date.today().isoformat()
    torch.save(
        {
            "model": net.state_dict(),
            "config": {"hidden": args.hidden, "width": FC.WIDTH, "style": name},
            "result": result,
        },
        ckpt_dir / f"style_{name}.pt",
    )
    print(f"style {name}: {json.dumps(result)}", flush=True)
    return result


def train_style_from_cache(name: str, args: argparse.Namespace) -> dict:
    """:func:`train_style` in a process of its own: its targets read from the cache."""
    content, by_style = targets([name])
    return train_style(name, args, content, by_style[name])


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    if FC.smoke():
        args.max_steps = args.max_steps or 3
    content, by_style = targets(None if args.all else args.style)  # made and cached once
    if args.jobs == 1:
        return {name: train_style(name, args, content, t) for name, t in by_style.items()}
    names = list(by_style)
    del content, by_style  # each process reads its own style from the cache
    # one style per process, each seeded as alone (the same networks as one after another);
    # spawned, as torch's thread pools do not survive a fork
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(args.jobs, mp_context=context) as pool:
        results = pool.map(train_style_from_cache, names, [args] * len(names))
        return dict(zip(names, results, strict=True))


if __name__ == "__main__":
    main()

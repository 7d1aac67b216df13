"""Train the fast style transformation networks (holden2017 section 3.3-3.4), one per style.

    python -m training.fast_style --style angry [--steps N] [--minutes M]
    python -m training.fast_style --all [--minutes-per-style M]

Needs the loss network (``python -m training.fast_autoencoder``): its weights, feature
statistics and validation split under ``checkpoints/fast/``. For style ``S`` the
content windows are Bandai training takes of the contents ``S`` was recorded with (any
style: the network learns to turn every style into ``S``), and each window's style target
is the mean Gram matrix of the loss network's hidden units over ``S``'s training takes of
the *same* content, as the paper pairs "angry run" with runs. Loss (paper eq. 4-10):

- content: hidden units of ``T(I)`` against those of ``I`` (relative squared error),
- style: Gram of ``T(I)``'s hidden units against the target (relative squared error),
- foot: world velocity of foot joints planted in ``I`` (leg lengths per second, squared),
- bone: squared bone-length error (leg lengths),
- trajectory: root velocity, turning and contact channels of ``T(I)`` against ``I``'s.

Writes ``checkpoints/fast/style_<name>.pt`` (overwritten) and logs to
``runs/fast/style_<name>``; ``--all`` also writes ``runs/fast/styles.json`` (final and
validation losses per style). ``MOTION_SMOKE=1`` runs a few steps.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import time
from collections import defaultdict

import numpy as np
import torch
from tqdm import tqdm

from motion import fast_features as FF
from training import fast_common as FC

WEIGHTS = {"content": 1.0, "style": 1.0, "foot": 0.5, "bone": 100.0, "traj": 1.0}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--style", action="append", help="style name (repeatable)")
    who.add_argument("--all", action="store_true", help="every style of the Bandai data")
    p.add_argument("--steps", type=int, default=400, help="steps per style")
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
    p.add_argument("--threads", type=int, default=None)
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


class StyleTrainer:
    """Data, targets and loss of one style; :meth:`train` fits a :class:`StyleNet`."""

    def __init__(self, style, train, val, ae, stats, args):
        self.style, self.ae, self.stats, self.args = style, ae, stats, args
        own = [c for c in train if c.style == style]
        self.contents = sorted({c.content for c in own})
        self.clips = [c for c in train if c.content in self.contents]
        self.val = [c for c in val if c.content in self.contents]
        self.n_style_clips = len(own)
        self.physics = FC.Physics(stats.mean, stats.std)
        grams: dict[str, list[torch.Tensor]] = defaultdict(list)
        with torch.no_grad():
            for c in own:
                x = torch.tensor(stats.normalize(c.features))[None]
                grams[c.content].append(FC.gram(ae.encode(x))[0])
        self.targets = {k: torch.stack(v).mean(0) for k, v in grams.items()}
        self.by_content = {k: [c for c in self.clips if c.content == k] for k in self.contents}

    def batch(self, clips_by_content, n: int, rng) -> tuple[torch.Tensor, torch.Tensor]:
        keys = [k for k in self.contents if clips_by_content.get(k)]
        picks = rng.choice(len(keys), size=n)
        x = np.stack(
            [
                FC.sample_windows(clips_by_content[keys[k]], 1, self.args.window, rng)[0]
                for k in picks
            ]
        )
        target = torch.stack([self.targets[keys[k]] for k in picks])
        return torch.tensor(self.stats.normalize(x)), target

    def losses(self, net, x: torch.Tensor, target: torch.Tensor) -> dict[str, torch.Tensor]:
        y = net(x)
        with torch.no_grad():
            h_in = self.ae.encode(x)
            planted = self.physics.raw(x)[..., FF.CONTACTS] > 0.5
        h_out = self.ae.encode(y)
        g_out = FC.gram(h_out)
        raw = self.physics.raw(y)
        root = slice(FF.POSITION_CHANNELS, FF.CHANNELS)
        return {
            "content": ((h_out - h_in) ** 2).mean() / (h_in**2).mean().clamp_min(1e-6),
            "style": ((g_out - target) ** 2).mean() / (target**2).mean().clamp_min(1e-6),
            "foot": self.physics.foot_loss(raw, planted),
            "bone": self.physics.bone_loss(raw),
            "traj": ((y[..., root] - x[..., root]) ** 2).mean(),
        }

    def total(self, parts: dict[str, torch.Tensor]) -> torch.Tensor:
        return sum(getattr(self.args, f"w_{k}") * v for k, v in parts.items())

    def train(self, log: FC.Logger) -> tuple[FC.StyleNet, dict]:
        args = self.args
        torch.manual_seed(args.seed)
        rng = np.random.default_rng(args.seed)
        net = FC.StyleNet(hidden=args.hidden)
        opt = torch.optim.Adam(net.parameters(), lr=args.lr)
        steps = min(args.steps, args.max_steps or args.steps)
        started = time.time()
        avg: dict[str, float] = {}
        bar = tqdm(range(1, steps + 1), desc=f"style {self.style}", mininterval=10)
        step = 0
        for step in bar:
            x, target = self.batch(self.by_content, args.batch, rng)
            parts = self.losses(net, x, target)
            loss = self.total(parts)
            opt.zero_grad()
            loss.backward()
            opt.step()
            for k, v in {**parts, "total": loss}.items():
                avg[k] = v.item() if k not in avg else 0.95 * avg[k] + 0.05 * v.item()
            if step % 20 == 0:
                bar.set_postfix(loss=f"{avg['total']:.4f}", style=f"{avg['style']:.4f}")
                log.scalars(step, {f"train/{k}": v for k, v in avg.items()})
            minutes = (time.time() - started) / 60
            if args.minutes_per_style and minutes > args.minutes_per_style:
                break
        result = {
            "steps": step,
            "minutes": round((time.time() - started) / 60, 2),
            "train": {k: round(v, 6) for k, v in avg.items()},
            "val": self.validate(net),
            "contents": self.contents,
            "style_clips": self.n_style_clips,
            "content_clips": len(self.clips),
        }
        log.scalars(step, {f"val/{k}": v for k, v in result["val"].items()})
        return net, result

    def validate(self, net) -> dict[str, float]:
        """Losses on held-out takes (fixed windows), and the untransformed baseline's."""
        by_content = {k: [c for c in self.val if c.content == k] for k in self.contents}
        if not any(by_content.values()):
            return {}
        x, target = self.batch(by_content, 32, np.random.default_rng(7))
        with torch.no_grad():
            parts = self.losses(net, x, target)
            base = self.losses(lambda z: z, x, target)
        out = {k: round(v.item(), 6) for k, v in parts.items()}
        out["style_identity"] = round(base["style"].item(), 6)
        return out


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    if FC.smoke():
        args.max_steps = args.max_steps or 3
    if args.threads:
        torch.set_num_threads(args.threads)
    ckpt_dir = FC.Path(args.checkpoint_dir)
    ae = load_autoencoder(ckpt_dir / "autoencoder.pt")
    stats = FF.FastStats.load(ckpt_dir / "stats.npz")
    bandai, _ = FC.load_encoded()
    train, val = FC.split(bandai)
    names = sorted({c.style for c in bandai}) if args.all else args.style
    unknown = set(names) - {c.style for c in bandai}
    if unknown:
        raise SystemExit(f"unknown styles: {sorted(unknown)}")
    summary = {}
    for name in names:
        trainer = StyleTrainer(name, train, val, ae, stats, args)
        log = FC.Logger(f"style_{name}", FC.Path(args.log_dir))
        net, result = trainer.train(log)
        log.close()
        result["trained_at"] = dt.date.today().isoformat()
        torch.save(
            {
                "model": net.state_dict(),
                "config": {"hidden": args.hidden, "width": FC.WIDTH, "style": name},
                "args": vars(args),
                "result": result,
            },
            ckpt_dir / f"style_{name}.pt",
        )
        summary[name] = result
        print(f"style {name}: {json.dumps(result)}", flush=True)
        if len(names) > 1:
            path = FC.Path(args.log_dir) / "styles.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(summary, indent=1))
    return summary


if __name__ == "__main__":
    main()

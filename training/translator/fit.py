"""Training of the translator on a library's aligned pairs (``training.translator.pairs``).

    python -m training.translator.fit --out checkpoints/translator.pt [--steps N]
        [--resume] [--threads 1] [--log runs/translator] [--device cuda]
        [--library LIB | --clips cache/carry/bandai.npz]

Each step draws a batch of content windows and asks the restyler, given a style code,
for the rotations of a real performance of the same action in that style, aligned in
time (``pairs``; the style may be the content's own, the target another take). The code
comes from the 3D style encoder on a window of another take of the style, or from the 2D
encoder on a projection of it. Losses, each a small
function below: rotations (standardised 6D), body positions relative to the hips, their
velocities, a style classifier on the codes (codes of one style together, so that a
style's mean code stands for it), and the 2D codes regressed on the 3D ones.

The schedule of the shipped model is ``training/translator/schedule.json``
(``make train-translator`` replays it). Checkpoints hold the weights, the network and
training configuration and the feature statistics; ``--resume`` continues with the
optimiser and random state kept in ``<out>.state`` (never committed; without it, from the
weights and step with a fresh optimiser).

The library (``training.library``: a folder of clips and ``labels.csv``) is Bandai's
(``training.bandai_library``, written under ``cache/`` on first use) unless ``--library``
names another; its labels say which takes are held out (the validation examples' content)
and which may be mirrored. ``--device`` trains on another torch device (the weights are
saved on the CPU all the same). ``--clips`` reads a library's clips from the cache files
``training.carry`` writes, for a machine without the data; with the alignment cache
(``$MOTION_CACHE_DIR/translator_alignments.npz``) holding every pair, such a machine needs
no librosa either.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from motion import canonical as C
from motion import features as Fe
from motion.styles import STYLE_ALIASES
from training import data as D
from training import distributed
from training.fk import RootLocalFK
from training.library import read_library
from training.translator.networks import (
    Discriminator,
    NetworkConfig,
    Translator,
    count_parameters,
)
from training.translator.pairs import (
    MIRRORED,
    Pairs,
    at_frames,
    encode_takes,
    load_alignments,
    save_alignments,
    window_of,
)

REPO = Path(__file__).resolve().parents[2]


@dataclass
class TrainConfig:
    steps: int = 12000
    batch: int = 32
    window: int = 64  # content frames per example
    style_window: int = 96  # frames the style encoder sees in training
    lr: float = 3e-4
    lr_final_fraction: float = 0.1  # cosine decay to this fraction of lr
    p_named: float = 0.5  # examples conditioned on the style's named code
    p_style2d: float = 0.2  # examples conditioned on the 2D encoder's code (else the 3D one's)
    views: int = 6  # 2D projections per take
    w_rot: float = 1.0
    w_pos: float = 10.0
    w_vel: float = 20.0
    w_code: float = 1.0
    w_2d: float = 1.0
    w_adv: float = 0.0
    w_track: float = 0.0
    seed: int = 0
    val_every: int = 500
    checkpoint_minutes: float = 10.0


def losses_of(
    out: torch.Tensor, target: torch.Tensor, norm: dict, fk: RootLocalFK
) -> dict[str, torch.Tensor]:
    """Rotation, position and velocity terms between standardised rotations ``out`` and
    ``target`` ``(B, 126, T)``."""
    pos_out = hips_relative(out, norm, fk)
    pos_target = hips_relative(target, norm, fk)
    return {
        "rot": F.l1_loss(out, target),
        "pos": F.l1_loss(pos_out, pos_target),
        "vel": F.l1_loss(pos_out[:, 1:] - pos_out[:, :-1], pos_target[:, 1:] - pos_target[:, :-1]),
    }


TRACKED = [int(np.flatnonzero(Fe.BODY == C.INDEX[n])[0])
           for n in ("Hand_L", "Hand_R", "Foot_L", "Foot_R")]  # fmt: skip


def path_decorrelation(positions: torch.Tensor, content: torch.Tensor) -> torch.Tensor:
    """1 - the correlation of the hands' and feet's paths about the hips with the content's,
    ``(B, T, 21, 3)`` each: each path's mean over the window removed, then sum(a . b) /
    sqrt(sum |a|^2 sum |b|^2) per joint. Free of where a joint is held and of how far it
    moves (a style's to choose), it asks only that it moves when and where the content's
    does."""
    a = positions[..., TRACKED, :]
    b = content[..., TRACKED, :]
    a = a - a.mean(dim=1, keepdim=True)
    b = b - b.mean(dim=1, keepdim=True)
    dot = (a * b).sum(dim=(1, 3))
    norm = torch.sqrt((a * a).sum(dim=(1, 3)) * (b * b).sum(dim=(1, 3)) + 1e-6)
    return (1 - dot / norm).mean()


def disc_input(positions: torch.Tensor, hips_height: torch.Tensor) -> torch.Tensor:
    """``(B, 127, T)`` what the discriminator reads of ``(B, T, 21, 3)`` positions relative
    to the hips and the hips height ``(B, T)`` (leg lengths): the positions and their
    change per frame, each scaled to about unit spread, and how far the hips are from a
    leg's length above the floor."""
    flat = positions.flatten(-2)
    vel = torch.cat([flat[:, 1:] - flat[:, :-1], flat[:, -1:] - flat[:, -2:-1]], dim=1)
    height = 10.0 * (hips_height[..., None] - 1.0)
    return torch.cat([2.0 * flat, 15.0 * vel, height], dim=-1).transpose(1, 2)


def hips_relative(rot: torch.Tensor, norm: dict, fk: RootLocalFK) -> torch.Tensor:
    """Body positions ``(B, T, 21, 3)`` relative to the hips, in leg lengths, of a
    standardised output ``(B, 127, T)`` (rotations, then the hips height)."""
    raw = rot.transpose(1, 2) * norm["out_std"] + norm["out_mean"]
    r6 = raw[..., : Fe.ROTATION_CHANNELS].unflatten(-1, (-1, 6))
    pos = fk(r6, torch.zeros(r6.shape[:2], device=r6.device))
    return pos - pos[..., :1, :]


def bandai_library_clips() -> list[D.Clip]:
    """The Bandai library's clips (``training.bandai_library``), written first if need be."""
    from training import bandai_library

    return read_library(bandai_library.write(bandai_library.default_folder()))


class Trainer:
    def __init__(
        self,
        cfg: TrainConfig,
        net_cfg: NetworkConfig,
        threads: int,
        device: str = "cpu",
        clips: list[D.Clip] | None = None,
    ) -> None:
        """``clips``: a library's (``training.library``; the Bandai library if not given),
        each labelled with its style and content and, in ``extra``, whether it is held out
        and may be mirrored."""
        torch.set_num_threads(threads)
        torch.manual_seed(cfg.seed)
        self.cfg = cfg
        self.device = torch.device(device)
        self.rng = np.random.default_rng(cfg.seed)
        clips = bandai_library_clips() if clips is None else clips
        unlabelled = [c.name for c in clips if "held_out" not in c.extra]
        if unlabelled:
            raise ValueError(
                f"{len(unlabelled)} clips carry no library labels (first {unlabelled[0]}): "
                "read them with training.library.read_library"
            )
        self.styles = sorted({c.style for c in clips})
        net_cfg.num_styles = len(self.styles)
        takes = encode_takes(clips, self.styles, cfg.views, self.rng)
        self.stats = Fe.compute_stats(
            {
                "content": [t.content for t in takes],
                "style3d": [t.style3d for t in takes],
                "style2d": [t.style2d.reshape(-1, Fe.STYLE2D_CHANNELS) for t in takes],
                "control": [Fe.control_features(t.content, t.style3d) for t in takes],
            }
        )
        for t in takes:
            t.inputs = Fe.restyler_input(t.content, t.style3d, self.stats)
        held_out_clips = {c.name for c in clips if c.extra["held_out"]}
        held_out = {t.name for t in takes if t.name.removesuffix(MIRRORED) in held_out_clips}
        self.pairs = Pairs([t for t in takes if t.name not in held_out], cfg.window, self.rng)
        self.val_pairs = Pairs(takes, cfg.window, self.rng, contents=held_out)
        self.alignment_cache = D.cache_dir() / "translator_alignments.npz"
        if distributed.rank() > 0:
            distributed.barrier()  # the first process aligns and caches every pair
        if self.alignment_cache.exists():
            self.pairs.alignments = load_alignments(self.alignment_cache)
        self.val_pairs.alignments = self.pairs.alignments
        self._align_every_pair()
        if distributed.rank() == 0:
            distributed.barrier()
        self.net = Translator(net_cfg).to(self.device)
        self.disc = Discriminator(net_cfg).to(self.device)
        self.disc_opt = torch.optim.Adam(self.disc.parameters(), lr=cfg.lr, betas=(0.5, 0.99))
        self.fk = RootLocalFK().to(self.device)
        mean, std = self.stats.get("output")
        self.norm = {
            "out_mean": torch.tensor(mean, device=self.device),
            "out_std": torch.tensor(std, device=self.device),
        }
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr)
        distributed.broadcast_parameters(self.net)
        distributed.broadcast_parameters(self.disc)
        if distributed.rank() > 0:  # the same data everywhere, batches of its own
            seeded = np.random.default_rng([cfg.seed, distributed.rank()])
            self.rng.bit_generator.state = seeded.bit_generator.state
        self.step = 0
        self.stages: list[str] = []  # schedule stages the weights have finished
        self.stage: str | None = None  # the stage these steps belong to (a resume continues it)
        self.validation: dict[str, float] = {}  # the last validation's losses
        print(
            f"{len(takes)} takes, styles {self.styles}, "
            f"restyler {count_parameters(self.net.restyler):,} parameters"
        )

    def _align_every_pair(self) -> None:
        """Aligns up front (and caches) every pair either set may draw that the cache lacks:
        then a machine given the cache never needs librosa, and a training writes the
        cache only as it starts, never in the middle of its steps."""
        missing = [
            (a, b)
            for pairs in (self.pairs, self.val_pairs)
            for a, b in pairs.every_pair()
            if (a.name, b.name) not in self.pairs.alignments
        ]
        for a, b in tqdm(missing, desc="aligning pairs", disable=not missing):
            self.val_pairs.aligned(a, b)
        if missing:
            save_alignments(self.alignment_cache, self.pairs.alignments)

    # --- batches ---------------------------------------------------------------------------

    def _content_input(self, take, start: int) -> np.ndarray:
        return take.inputs[start : start + self.cfg.window]

    def batch(self, pairs: Pairs | None = None) -> dict[str, torch.Tensor]:
        """Content windows ``(B, 25, T)`` (restyler input), standardised target rotations
        ``(B, 126, T)``, the style windows in 3D ``(B, 63, Ts)`` and seen in 2D ``(B, 32,
        Ts)``, which examples take the 2D code, and the styles."""
        cfg = self.cfg
        pairs = pairs or self.pairs
        rows: dict[str, list] = {
            k: [] for k in ("content", "content_pos", "target", "style3d", "style2d", "real")
        }
        source, labels, real_labels = [], [], []
        for _ in range(cfg.batch):
            take, start, target_take, frames = pairs.draw_pair()
            target = at_frames(target_take.content[:, : Fe.OUTPUT_CHANNELS], frames)
            style_take, style_start = self.pairs.style_window(target_take.style, cfg.style_window)
            view = style_take.style2d[self.rng.integers(len(style_take.style2d))]
            rows["content"].append(self._content_input(take, start))
            rows["content_pos"].append(take.style3d[start : start + cfg.window])
            rows["target"].append(Fe.standardize(target, self.stats, "output"))
            for kind, x in (("style3d", style_take.style3d), ("style2d", view)):
                x = Fe.standardize(x, self.stats, kind)
                rows[kind].append(window_of(x, style_start, cfg.style_window))
            u = self.rng.random()
            source.append(0 if u < cfg.p_named else 2 if u < cfg.p_named + cfg.p_style2d else 1)
            labels.append(style_take.style)
            real_style = int(self.pairs.styles[self.rng.integers(len(self.pairs.styles))])
            real_take, real_start = self.pairs.style_window(real_style, cfg.window)
            real = np.concatenate(
                [real_take.style3d, real_take.content[:, Fe.ROTATION_CHANNELS, None]], axis=1
            )
            rows["real"].append(window_of(real, real_start, cfg.window))
            real_labels.append(real_style)
        batch = {
            k: torch.from_numpy(np.stack(v)).transpose(1, 2).contiguous() for k, v in rows.items()
        }
        batch |= {
            "source": torch.tensor(source),  # 0 named, 1 3D encoder, 2 2D encoder
            "labels": torch.tensor(labels),
            "real_labels": torch.tensor(real_labels),
        }
        return {k: v.to(self.device) for k, v in batch.items()}

    # --- step ------------------------------------------------------------------------------

    def forward(self, b: dict) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """The generator's loss terms of a batch, and its output rotations."""
        net = self.net
        named = net.named(b["labels"])
        code3 = net.style3d(b["style3d"])
        code2 = net.style2d(b["style2d"])
        source = b["source"][:, None]
        codes = torch.where(source == 0, named, torch.where(source == 1, code3, code2))
        out = net.restyler(b["content"], codes)
        terms = losses_of(out, b["target"], self.norm, self.fk)
        if self.cfg.w_track:
            content = b["content_pos"].transpose(1, 2).unflatten(-1, (-1, 3))
            terms["track"] = path_decorrelation(
                hips_relative(out, self.norm, self.fk), content - content[..., :1, :]
            )
        terms["code"] = F.mse_loss(code3, named.detach())
        terms["2d"] = F.mse_loss(code2, named.detach())
        if self.cfg.w_adv:
            fake = disc_input(hips_relative(out, self.norm, self.fk), self.hips_height(out))
            terms["adv"] = ((self.disc(fake, b["labels"]) - 1) ** 2).mean()
        return terms, out

    def hips_height(self, out: torch.Tensor) -> torch.Tensor:
        """The hips height ``(B, T)`` in leg lengths of a standardised output."""
        k = Fe.ROTATION_CHANNELS
        return out[:, k] * self.norm["out_std"][k] + self.norm["out_mean"][k]

    def disc_step(self, b: dict, out: torch.Tensor) -> dict[str, float]:
        """One discriminator update (least squares): real Bandai windows of their style
        against this step's restyled windows of their target style."""
        real = b["real"].transpose(1, 2)
        height = real[..., -1]
        real = real[..., :-1].unflatten(-1, (-1, 3))
        real = disc_input(real - real[..., :1, :], height)
        out = out.detach()
        fake = disc_input(hips_relative(out, self.norm, self.fk), self.hips_height(out))
        loss_real = ((self.disc(real, b["real_labels"]) - 1) ** 2).mean()
        loss_fake = (self.disc(fake, b["labels"]) ** 2).mean()
        loss = loss_real + loss_fake
        self.disc_opt.zero_grad(set_to_none=True)
        loss.backward()
        distributed.average_gradients(self.disc.parameters())
        self.disc_opt.step()
        return {
            "d_real": float(loss_real.detach()),
            "d_fake": float(loss_fake.detach()),
        }

    def train_step(self) -> dict[str, float]:
        cfg = self.cfg
        b = self.batch()
        terms, out = self.forward(b)
        loss = sum(getattr(cfg, f"w_{k}") * v for k, v in terms.items())
        lr = self.learning_rate()
        for group in self.opt.param_groups + self.disc_opt.param_groups:
            group["lr"] = lr
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        distributed.average_gradients(self.net.parameters())
        torch.nn.utils.clip_grad_norm_(self.net.parameters(), 5.0)
        self.opt.step()
        self.step += 1
        scores = self.disc_step(b, out) if cfg.w_adv else {}
        return (
            {k: float(v.detach()) for k, v in terms.items()}
            | scores
            | {"loss": float(loss.detach()), "lr": lr}
        )

    def learning_rate(self) -> float:
        cfg = self.cfg
        progress = min(self.step / max(cfg.steps, 1), 1.0)
        cosine = 0.5 * (1 + math.cos(math.pi * progress))
        return cfg.lr * (cfg.lr_final_fraction + (1 - cfg.lr_final_fraction) * cosine)

    @torch.no_grad()
    def validate(self, batches: list[dict]) -> dict[str, float]:
        self.net.eval()
        sums: dict[str, float] = {}
        for b in batches:
            for k, v in self.forward(b)[0].items():
                sums[k] = sums.get(k, 0.0) + float(v) / len(batches)
        self.net.train()
        return sums

    # --- checkpoints -----------------------------------------------------------------------

    def save(self, path: Path, finished: str | None = None) -> None:
        """Weights, configurations, statistics and styles in ``path``; the optimiser, the
        random state and the weights again (for ``--resume``) in ``path.state``, never
        committed, written first: a run killed between the two writes resumes from the
        state, never older than the payload beside it. Under ``torchrun`` every process
        calls it (each one's random state is kept), the first writes."""
        rngs = distributed.gather(self.rng.bit_generator.state)
        if distributed.rank() > 0:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        stats = {f"{k}_{s}": torch.tensor(getattr(self.stats, s)[k])
                 for k in self.stats.mean for s in ("mean", "std")}  # fmt: skip
        payload = {
            "weights": {k: v.cpu() for k, v in self.net.state_dict().items()},
            "network": self.net.cfg.to_dict(),
            "train": asdict(self.cfg),
            "styles": self.styles,
            "aliases": {
                a: s for a, s in STYLE_ALIASES.items() if s in self.styles and a not in self.styles
            },
            "stats": stats,
            "step": self.step,
            "stages": self.stages + ([finished] if finished else []),
            "stage": self.stage,
            "validation": self.validation,
            "processes": distributed.world(),
        }
        state = {
            "weights": payload["weights"],
            "opt": self.opt.state_dict(),
            "disc": self.disc.state_dict(),
            "disc_opt": self.disc_opt.state_dict(),
            "step": self.step,
            "rng": rngs[0],
            "rngs": rngs,
        }
        torch.save(state, str(path) + ".state.tmp")
        os.replace(str(path) + ".state.tmp", str(path) + ".state")
        torch.save(payload, str(path) + ".tmp")
        os.replace(str(path) + ".tmp", path)

    def load(self, path: Path, optimiser: bool) -> None:
        payload = torch.load(path, weights_only=False, map_location=self.device)
        self.net.load_state_dict(payload["weights"])
        self.step = int(payload["step"])
        self.stages = list(payload.get("stages", []))
        self.validation = dict(payload.get("validation", {}))
        state_path = Path(str(path) + ".state")
        if optimiser:
            state = torch.load(state_path, weights_only=False, map_location=self.device)
            if "weights" in state and state["step"] > self.step:  # killed between the writes
                self.net.load_state_dict(state["weights"])
                self.step = int(state["step"])
            self.opt.load_state_dict(state["opt"])
            self.disc.load_state_dict(state["disc"])
            self.disc_opt.load_state_dict(state["disc_opt"])
            rngs = state.get("rngs", [])
            mine = rngs[distributed.rank()] if len(rngs) == distributed.world() else state["rng"]
            self.rng.bit_generator.state = mine


def parse_args(argv: list[str] | None = None) -> tuple[argparse.Namespace, TrainConfig]:
    """The command line, and the training configuration it asks for."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "checkpoints" / "translator.pt")
    parser.add_argument("--init", type=Path, help="start from these weights (no optimiser)")
    parser.add_argument("--resume", action="store_true", help="continue --out with its optimiser")
    parser.add_argument("--threads", type=int, default=1)
    # --runs too: torchrun's own parser takes --log for an abbreviation of its --log-dir
    parser.add_argument("--log", "--runs", type=Path, default=REPO / "runs" / "translator")
    parser.add_argument("--max-minutes", type=float, default=None)
    parser.add_argument("--channels", type=int, default=NetworkConfig().channels)
    parser.add_argument("--stage", help="the schedule stage this run is (recorded when done)")
    parser.add_argument("--device", default="cpu", help="torch device to train on (cuda, ...)")
    parser.add_argument(
        "--library", type=Path, help="the library to train on (training.library; Bandai's)"
    )
    parser.add_argument(
        "--clips", type=Path, nargs="+", help="a library's clips from training.data cache files"
    )
    for name, value in asdict(TrainConfig()).items():
        parser.add_argument(f"--{name.replace('_', '-')}", type=type(value), default=value)
    args = parser.parse_args(argv)
    return args, TrainConfig(**{k: getattr(args, k) for k in asdict(TrainConfig())})


def main(argv: list[str] | None = None) -> int:
    args, cfg = parse_args(argv)
    owns_group = not distributed.started()  # else the caller goes on with it
    args.device = distributed.start(args.device)
    first = distributed.rank() == 0
    if os.environ.get("MOTION_SMOKE"):
        cfg.steps, cfg.val_every = 3, 2
    clips = None
    if args.clips:
        clips = [c for p in args.clips for c in D.read_clips(p)]
    elif args.library:
        clips = read_library(args.library)
    trainer = Trainer(cfg, NetworkConfig(channels=args.channels), args.threads, args.device, clips)
    trainer.stage = args.stage
    # drawing these moves the training's generator too (style windows), so they are drawn
    # before a resume restores it: a resumed run draws what an uninterrupted one would
    saved = trainer.rng, trainer.val_pairs.rng
    trainer.rng = trainer.val_pairs.rng = np.random.default_rng(12345)
    val = [trainer.batch(trainer.val_pairs) for _ in range(8 if trainer.val_pairs.drawable else 0)]
    trainer.rng, trainer.val_pairs.rng = saved
    if args.resume:  # a weights-only copy (committed) continues with a fresh optimiser
        trainer.load(args.out, optimiser=Path(f"{args.out}.state").exists())
    elif args.init:
        trainer.load(args.init, optimiser=False)
        trainer.step = 0
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(args.log)) if first else None
    started = last_save = time.time()
    first_step = trainer.step
    progress = tqdm(
        total=cfg.steps, initial=trainer.step, desc=f"translator {args.stage or ''}".strip(),
        unit="step", mininterval=10, smoothing=0.05, disable=not first,
    )  # fmt: skip
    while trainer.step < cfg.steps:
        terms = trainer.train_step()
        progress.update(1)
        if trainer.step % 50 == 0 and first:
            for k, v in terms.items():
                writer.add_scalar(f"train/{k}", v, trainer.step)
        if first and (trainer.step % cfg.val_every == 0 or trainer.step == cfg.steps):
            scores = trainer.validate(val)
            trainer.validation = {k: round(v, 6) for k, v in scores.items()}
            for k, v in scores.items():
                writer.add_scalar(f"val/{k}", v, trainer.step)
            rate = (trainer.step - first_step) / max(time.time() - started, 1e-9)
            progress.write(f"step {trainer.step} "
                           + " ".join(f"{k} {v:.4f}" for k, v in scores.items())
                           + f" ({rate:.2f} steps/s)")  # fmt: skip
        out_of_time = distributed.agree(
            bool(args.max_minutes) and time.time() - started > 60 * args.max_minutes
        )
        if distributed.agree(time.time() - last_save > 60 * cfg.checkpoint_minutes) or out_of_time:
            trainer.save(args.out)
            last_save = time.time()
        if out_of_time:
            break
    trainer.save(args.out, finished=args.stage if trainer.step >= cfg.steps else None)
    progress.close()
    spread = distributed.spread(trainer.net)
    if distributed.world() > 1:
        if first:
            print(f"{distributed.world()} processes, weights apart by at most {spread:.2e}")
        if owns_group:
            distributed.stop()
        if spread > 0:
            raise RuntimeError(f"the processes' weights drifted apart ({spread:.2e})")
    if writer is not None:
        writer.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

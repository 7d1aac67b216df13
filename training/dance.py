"""Music to dance (jacob2019, made to work): network and training loop (data windows in
``training.dance_data``, losses in ``training.dance_losses``).

    python -m training.dance [--max-steps N] [--minutes M] [--resume | --init CKPT]
        [--device cuda --prepared cache/carry/dance_prepared.npz]  # a lent GPU machine
    python -m training.dance_schedule          # the shipped model's stages (make train-dance)
    python -m training.eval_dance              # held-out songs, through the shipped engine

Network (per frame at 30 fps): the song's features (``motion.dance_features.song_features``:
log-mel, the thesis's spectral summary, onset, beat phase) -> two fully connected layers ->
audio code; [code, genre embedding, previous pose] -> two stacked LSTM cells (dropout
between) -> the next pose (``motion.dance_features`` encoding: 6D rotations with the hips
relative to the facing frame, root velocity and turning in the facing frame, hips height,
foot contacts). The genre is given (one-hot) or predicted from the music by a classifier
head on the time-averaged audio code, whose probabilities then stand in for the one-hot.
With ``--film`` the genre also scales and shifts the input of the second cell and the output
of the last (FiLM), so it reaches every layer, not only the first cell's input.

Training: windows of ``--window`` frames from the Dance with Melody dances (retimed onto
their songs' clocks as ``training/dance_alignment.json`` says; beat phase only where the
alignment was verified, "unknown" elsewhere) and, with probability ``--cmu-share``, CMU
salsa / Indian / modern dances with silent audio (a motion prior for the network). Auto-
conditioning (Zhou et al. 2018): ground-truth stretches of ``--gt-frames`` alternate with
self-fed stretches whose length ramps up to ``--cond-frames``, so long generation neither
freezes nor drifts. Losses: rotation/root features, forward-kinematics positions (root-local,
leg lengths), Laban effort (angular-velocity energy per window, log ratio), foot skating
under ground-truth contacts, genre cross-entropy. Whole songs are held out by take. With
``--swap-share`` some music windows are asked another genre and judged by a convolutional
classifier of real dances, a per-genre kinetic prior, a diversity guard and a skating loss
on their stillest foot instead (``training.dance_genre``: why and how). Validation
runs free on fixed windows of the held-out songs and, as ``training_songs_feat``, of the
training songs: the gap between the two is how much of the dance is memorised.

Writes ``checkpoints/dance.pt`` (weights, step, config and the feature statistics: what an
export needs) and the optimiser beside it in ``dance.pt.state`` (for ``--resume``, never
committed), TensorBoard scalars in ``runs/dance``; ``MOTION_SMOKE=1`` stops after a few steps.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from motion import dance_features as DF
from training import dance_genre as TG
from training.dance_data import Sequence, WindowSampler, load_prepared, prepare, start_poses
from training.dance_losses import Losses

REPO = Path(__file__).resolve().parent.parent
CHECKPOINT = REPO / "checkpoints" / "dance.pt"
RUNS = REPO / "runs" / "dance"
FOLDS = (
    ("DANCE_C_8", "DANCE_R_5", "DANCE_W_26", "DANCE_W_8"),
    ("DANCE_C_4", "DANCE_R_2", "DANCE_W_14", "DANCE_W_16"),
)
"""Held-out songs of each fold: one cha-cha, one rumba and one waltz with verified
alignment, one waltz whose tempo needed correcting (tango has one dance only: it stays in
training). The shipped model is fold 0's; a fold's model never sees its songs."""
VAL_TAKES = FOLDS[0]

WEIGHTS = {
    "feat": 1.0,
    "pos": 4.0,
    "effort": 0.2,
    "skate": 0.05,
    "genre": 0.1,
    "judge": 0.0,
    "prior": 0.0,
    "match": 0.0,
    "diversity": 0.0,
    "free_skate": 0.0,
}
GUARDS = ("judge", "prior", "match", "diversity", "free_skate")
"""The loss terms that need the judge of real dances (``training.dance_genre``)."""
SCHEDULE = Path(__file__).with_name("dance_schedule.json")


def split(seqs: list[Sequence], val_takes=VAL_TAKES) -> tuple[list[Sequence], list[Sequence]]:
    """Train and validation sequences by whole song."""
    return [s for s in seqs if s.name not in val_takes], [s for s in seqs if s.name in val_takes]


def fold_of(ckpt: dict) -> int:
    """The fold a checkpoint was trained on (0 before checkpoints recorded it)."""
    return int(ckpt.get("train_config", {}).get("fold", 0))


def require_fold(ckpt: dict, fold: int, path) -> None:
    """``SystemExit`` unless checkpoint ``ckpt`` (read from ``path``) is fold ``fold``'s:
    another fold's has seen this fold's songs."""
    if fold_of(ckpt) != fold:
        raise SystemExit(f"{path} is fold {fold_of(ckpt)}'s, not fold {fold}'s")


def held_out_takes(ckpt: dict) -> tuple[str, ...]:
    """The songs a checkpoint never saw."""
    return FOLDS[fold_of(ckpt)]


# --------------------------------------------------------------------------- network


@dataclass
class Config:
    hidden: int = 256
    code: int = 128
    audio_hidden: int = 256
    genre_dim: int = 16
    dropout: float = 0.25
    film: bool = False  # the genre also scales and shifts each LSTM layer's output


class DanceNet(nn.Module):
    """Audio MLP, genre classifier head, genre embedding and two stacked LSTM cells.

    ``encode_audio(audio (B, T, A))`` -> ``code (B, T, code)``, ``logits (B, 4)``;
    ``step(code (B, code), genre (B, G), prev (B, M), h1, c1, h2, c2)`` -> ``pose (B, M)``
    and the new states; all in standardised units.
    """

    def __init__(self, config: Config | None = None) -> None:
        super().__init__()
        cfg = self.config = config or Config()
        self.audio = nn.Sequential(
            nn.Linear(DF.AUDIO_CHANNELS, cfg.audio_hidden),
            nn.ReLU(),
            nn.Dropout(0.1),
            nn.Linear(cfg.audio_hidden, cfg.code),
            nn.ReLU(),
        )
        self.classifier = nn.Sequential(
            nn.Linear(cfg.code, 64), nn.ReLU(), nn.Linear(64, len(DF.MUSIC_GENRES))
        )
        self.genre = nn.Linear(len(DF.GENRES), cfg.genre_dim, bias=False)
        self.cell1 = nn.LSTMCell(cfg.code + cfg.genre_dim + DF.MOTION_CHANNELS, cfg.hidden)
        self.cell2 = nn.LSTMCell(cfg.hidden, cfg.hidden)
        self.drop = nn.Dropout(cfg.dropout)
        self.out = nn.Linear(cfg.hidden, DF.MOTION_CHANNELS)
        if cfg.film:  # zero: a network fine-tuned from one without starts where it was
            self.film1 = nn.Linear(len(DF.GENRES), 2 * cfg.hidden)
            self.film2 = nn.Linear(len(DF.GENRES), 2 * cfg.hidden)
            for layer in (self.film1, self.film2):
                nn.init.zeros_(layer.weight)
                nn.init.zeros_(layer.bias)

    def encode_audio(self, audio: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        code = self.audio(audio)
        return code, self.classifier(code.mean(dim=1))

    def init_state(self, batch: int) -> tuple[torch.Tensor, ...]:
        z = torch.zeros(batch, self.config.hidden, device=self.out.weight.device)
        return z, z, z, z

    def step(self, code, genre, prev, h1, c1, h2, c2):
        x = torch.cat([code, self.genre(genre), prev], dim=-1)
        h1, c1 = self.cell1(x, (h1, c1))
        if not self.config.film:
            h2, c2 = self.cell2(self.drop(h1), (h2, c2))
            return self.out(h2), h1, c1, h2, c2
        h2, c2 = self.cell2(self._film(self.film1, genre, self.drop(h1)), (h2, c2))
        return self.out(self._film(self.film2, genre, h2)), h1, c1, h2, c2

    def _film(self, layer: nn.Linear, genre: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """``x * (1 + scale) + shift``, both linear in the genre; the weights are split (and
        the 1 folded into the bias) outside the product, so an export folds them into two
        constant matrices instead of slicing the product every frame."""
        n = self.config.hidden
        scale = nn.functional.linear(genre, layer.weight[:n], layer.bias[:n] + 1)
        return x * scale + nn.functional.linear(genre, layer.weight[n:], layer.bias[n:])

    def rollout(
        self, code, genre, motion, gt_mask: torch.Tensor | None = None, warm: int = 0
    ) -> torch.Tensor:
        """Poses ``(B, T - 1, M)`` for frames 1.. of ``motion (B, T, M)``: frame 0 is given;
        each later frame is fed back its own prediction, or the ground truth where
        ``gt_mask`` (``(T,)``, or ``(B, T)`` per window) is true (and for the first ``warm``
        frames)."""
        state = self.init_state(motion.shape[0])
        prev = motion[:, 0]
        if gt_mask is not None and gt_mask.dim() == 1:
            gt_mask = gt_mask.tolist()  # read each frame without a device round trip
        outs = []
        for t in range(1, motion.shape[1]):
            pose, *state = self.step(code[:, t], genre, prev, *state)
            outs.append(pose)
            if t < warm:
                prev = motion[:, t]
            elif gt_mask is None:
                prev = pose
            elif isinstance(gt_mask, list):
                prev = motion[:, t] if gt_mask[t] else pose
            else:
                prev = torch.where(gt_mask[:, t, None], motion[:, t], pose)
        return torch.stack(outs, dim=1)


def to_device(batch: tuple[torch.Tensor, ...], device: torch.device) -> tuple[torch.Tensor, ...]:
    return tuple(t.to(device) for t in batch)


def ac_mask(frames: int, gt: int, cond: int, rng: np.random.Generator) -> torch.Tensor:
    """``(frames,)`` bool: ground-truth stretches of ``gt`` frames alternating with self-fed
    stretches of ``cond`` frames, at a random phase."""
    period = gt + cond
    phase = int(rng.integers(0, period))
    return torch.from_numpy(((np.arange(frames) + phase) % period) < gt)


# --------------------------------------------------------------------------- training


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=20000, help="schedule length (lr decay)")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many steps")
    p.add_argument("--stop-step", type=int, default=None,
                   help="end the run at this step, the learning rate still decaying over --steps")  # fmt: skip
    p.add_argument("--minutes", type=float, default=None, help="stop after this wall time")
    p.add_argument("--resume", action="store_true", help=f"continue from {CHECKPOINT.name}")
    p.add_argument("--init", type=Path, default=None,
                   help="start from this checkpoint's weights, statistics and start poses "
                   "(a new schedule from step 0; layers it lacks start at zero)")  # fmt: skip
    p.add_argument("--film", action="store_true", help="genre FiLM on both LSTM layers")
    p.add_argument("--stage", default=None,
                   help="the schedule stage this run is (recorded once its steps are done)")  # fmt: skip
    p.add_argument("--swap-share", type=float, default=0.0,
                   help="share of music windows asked another genre (judge and prior only)")  # fmt: skip
    p.add_argument("--guard-all", action="store_true",
                   help="kinetic match and diversity guard on every music window, not only "
                   "the swapped ones")  # fmt: skip
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--window", type=int, default=96, help="frames per training window")
    p.add_argument("--gt-frames", type=int, default=5, help="ground-truth stretch length")
    p.add_argument("--cond-frames", type=int, default=20, help="self-fed stretch (final)")
    p.add_argument("--cond-ramp", type=int, default=8000, help="steps to reach --cond-frames")
    p.add_argument("--warm", type=int, default=8, help="ground-truth frames at window start")
    p.add_argument("--cmu-share", type=float, default=0.15)
    p.add_argument("--predicted-genre", type=float, default=0.3,
                   help="share of music windows conditioned on the predicted genre")  # fmt: skip
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--hidden", type=int, default=Config.hidden)
    for name, value in WEIGHTS.items():
        p.add_argument(f"--w-{name.replace('_', '-')}", dest=f"w_{name}", type=float,
                       default=value, help=f"{name} loss weight")  # fmt: skip
    p.add_argument("--val-every", type=int, default=500)
    p.add_argument("--save-every", type=int, default=500)
    p.add_argument("--checkpoint", type=Path, default=CHECKPOINT)
    p.add_argument("--log-dir", type=Path, default=RUNS)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--device", default="cpu", help="torch device to train on (cuda, ...)")
    p.add_argument("--prepared", type=Path, default=None,
                   help="the sequences from this file (`python -m training.carry dance`), "
                   "not from the data folder")  # fmt: skip
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--fold",
        type=int,
        default=0,
        choices=range(len(FOLDS)),
        help="the held-out songs (FOLDS): a fold's model never sees its songs",
    )
    args = p.parse_args(argv)
    if os.environ.get("MOTION_SMOKE"):
        args.max_steps = min(args.max_steps or 3, 3)
    return args


def save_checkpoint(
    path: Path, model, optimiser, step, args, stats, poses, best, stages=()
) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
    tmp = path.with_suffix(".tmp")
    torch.save(
        {
            "model": model.state_dict(),
            "step": step,
            "net_config": dataclasses.asdict(model.config),
            "train_config": config,
            "stats": stats.arrays(),
            "start_poses": poses,
            "best_val": best,
            "stages": list(stages),
            "saved_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        },
        tmp,
    )
    os.replace(tmp, path)
    torch.save(optimiser.state_dict(), tmp)
    os.replace(tmp, optimiser_path(path))


def optimiser_path(checkpoint: Path) -> Path:
    return checkpoint.with_name(checkpoint.name + ".state")


def load_checkpoint(path: Path = CHECKPOINT) -> tuple[DanceNet, DF.DanceStats, dict]:
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    model = DanceNet(Config(**ckpt["net_config"]))
    model.load_state_dict(ckpt["model"])
    model.eval()
    return model, DF.DanceStats.from_arrays(ckpt["stats"]), ckpt


def init_from(path: Path, config: Config) -> tuple[DanceNet, DF.DanceStats, dict]:
    """A network with the weights of checkpoint ``path`` and its sizes, FiLM as ``config``
    says (layers the checkpoint lacks keep their zero start); the checkpoint."""
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    config = dataclasses.replace(config, **{k: v for k, v in ckpt["net_config"].items()
                                            if k != "film"})  # fmt: skip
    model = DanceNet(config)
    missing, unexpected = model.load_state_dict(ckpt["model"], strict=False)
    if unexpected or any(not k.startswith("film") for k in missing):
        raise ValueError(f"{path} does not fit: missing {missing}, unexpected {unexpected}")
    model.train()
    return model, DF.DanceStats.from_arrays(ckpt["stats"]), ckpt


def train_step(
    model, losses, batch, args, rng, step, weights, judge=None
) -> dict[str, torch.Tensor]:
    audio, motion, genre, music = batch
    device = audio.device
    code, logits = model.encode_audio(audio)
    asked = genre.clone()
    swapped = TG.swap_genres(asked, music, args.swap_share, rng)
    onehot = nn.functional.one_hot(asked, len(DF.GENRES)).float()
    cond_vec = onehot
    if args.predicted_genre > 0:
        probs = torch.softmax(logits.detach(), dim=-1)
        predicted = torch.zeros_like(onehot)
        predicted[:, : len(DF.MUSIC_GENRES)] = probs
        use = music & ~swapped & (torch.rand(len(genre)).to(device) < args.predicted_genre)
        cond_vec = torch.where(use[:, None], predicted, onehot)
    cond = max(1, min(args.cond_frames, 1 + step * args.cond_frames // max(args.cond_ramp, 1)))
    mask = ac_mask(motion.shape[1], args.gt_frames, cond, rng).to(device)
    if swapped.any():  # a swapped window has no ground truth to feed back
        mask = mask[None].expand(len(genre), -1) & ~swapped[:, None]
    pred = model.rollout(code, cond_vec, motion, mask, warm=args.warm)
    if swapped.all():
        parts = {k: torch.zeros((), device=device) for k in ("feat", "pos", "effort", "skate")}
    else:
        parts = losses(pred[~swapped], motion[~swapped, 1:])
    if music.any():
        parts["genre"] = nn.functional.cross_entropy(logits[music], genre[music])
    else:
        parts["genre"] = torch.zeros((), device=device)
    for k in GUARDS:
        parts[k] = torch.zeros((), device=device)
    if judge is not None and music.any():
        frames, kinetic, pos, raw = TG.window_inputs(losses, pred[music][:, args.warm - 1 :])
        parts["judge"] = judge.judged(judge(frames), asked[music])
        free = swapped[music]
        if free.any():
            parts["prior"] = judge.prior(kinetic[free], asked[swapped])
            guard = torch.ones_like(free) if args.guard_all else free
            parts["match"] = judge.match(kinetic[guard], asked[music][guard])
            parts["diversity"] = judge.diversity(kinetic[guard], asked[music][guard])
            skate = TG.free_skating(pos[free], raw[free], losses.feet)
            parts["free_skate"] = judge.skating(skate, asked[swapped])
    parts["total"] = sum(weights[k] * parts[k] for k in weights)
    return parts


@torch.no_grad()
def validate(model, losses, val_batches, judge=None) -> dict[str, float]:
    """Mean losses over fixed validation windows, free-running after the warm-up frames;
    with a judge, the share of windows asked another genre (the next one) it names so."""
    model.eval()
    totals: dict[str, float] = {}
    correct = count = judged = 0
    for audio, motion, genre, music in val_batches:
        code, logits = model.encode_audio(audio)
        onehot = nn.functional.one_hot(genre, len(DF.GENRES)).float()
        pred = model.rollout(code, onehot, motion, None, warm=8)
        for k, v in losses(pred, motion[:, 1:]).items():
            totals[k] = totals.get(k, 0.0) + float(v) / len(val_batches)
        correct += int((logits[music].argmax(-1) == genre[music]).sum())
        count += int(music.sum())
        if judge is not None:
            other = (genre[music] + 1) % len(DF.MUSIC_GENRES)
            asked = nn.functional.one_hot(other, len(DF.GENRES)).float()
            pred = model.rollout(code[music], asked, motion[music], None, warm=8)
            named = judge(TG.window_inputs(losses, pred[:, 7:])[0]).argmax(-1)
            judged += int((named == other).sum())
    totals["genre_acc"] = correct / max(count, 1)
    if judge is not None:
        totals["swapped_judged"] = judged / max(count, 1)
    model.train()
    return totals


def run_bounds(step: int, args: argparse.Namespace) -> tuple[int, int]:
    """The stage's last step (``--steps``, or ``--stop-step`` before it) and where a run
    from ``step`` stops (``--max-steps`` later, at most that last step)."""
    last = min(args.steps, args.stop_step or args.steps)
    return last, (min(step + args.max_steps, last) if args.max_steps else last)


def train(args: argparse.Namespace) -> None:
    from tqdm import tqdm

    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    device = torch.device(args.device)
    seqs = load_prepared(args.prepared) if args.prepared else prepare()
    train_seqs, val_seqs = split(seqs, FOLDS[args.fold])
    weights = {k: getattr(args, f"w_{k}") for k in WEIGHTS}
    if args.resume and args.checkpoint.exists():
        model, stats, ckpt = load_checkpoint(args.checkpoint)
        require_fold(ckpt, args.fold, args.checkpoint)
        model.train()
        poses, step, best = ckpt["start_poses"], int(ckpt["step"]), ckpt.get("best_val")
        stages = list(ckpt.get("stages", []))
    elif args.init is not None:
        model, stats, start = init_from(args.init, Config(film=args.film))
        require_fold(start, args.fold, args.init)
        poses, stages, step, best, ckpt = (
            start["start_poses"],
            start.get("stages", []),
            0,
            None,
            None,
        )
    else:
        stats = DF.DanceStats.fit([s.audio for s in train_seqs if s.has_music],
                                  [s.motion for s in train_seqs])  # fmt: skip
        model, step, best, ckpt = (
            DanceNet(Config(hidden=args.hidden, film=args.film)),
            0,
            None,
            None,
        )
        poses, stages = start_poses(train_seqs), []
    model.to(device)
    losses = Losses(stats).to(device)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    if ckpt is not None and optimiser_path(args.checkpoint).exists():
        optimiser.load_state_dict(
            torch.load(optimiser_path(args.checkpoint), weights_only=False, map_location=device)
        )
    sampler = WindowSampler(train_seqs, stats, args.window, args.cmu_share, args.seed + step)
    val_sampler = WindowSampler(val_seqs, stats, args.window, 0.0, 1234)
    val_batches = [to_device(val_sampler.batch(16, beat_dropout=0.0), device) for _ in range(4)]
    seen_sampler = WindowSampler(train_seqs, stats, args.window, 0.0, 77)
    seen_batches = [to_device(seen_sampler.batch(16, beat_dropout=0.0), device) for _ in range(4)]
    judge = None
    if any(weights[k] > 0 for k in GUARDS):
        judge = TG.fit_judge(
            WindowSampler(train_seqs, stats, args.window, 0.0, args.seed + 99),
            WindowSampler(val_seqs, stats, args.window, 0.0, 4321),
            Losses(stats),  # the real windows are drawn on the CPU
            skip=args.warm - 1,
        ).to(device)
    tb = None
    try:
        from torch.utils.tensorboard import SummaryWriter

        tb = SummaryWriter(str(args.log_dir))
    except ImportError:  # pragma: no cover
        pass
    total_steps = args.steps
    last, stop_at = run_bounds(step, args)
    deadline = time.time() + 60 * args.minutes if args.minutes else math.inf
    model.train()
    bar = tqdm(total=stop_at - step, desc="dance", unit="it")
    started, first_step = time.time(), step
    while step < stop_at and time.time() < deadline:
        lr = args.lr * 0.5 * (1 + math.cos(math.pi * min(step / total_steps, 1.0)))
        for group in optimiser.param_groups:
            group["lr"] = lr
        batch = to_device(sampler.batch(args.batch), device)
        parts = train_step(model, losses, batch, args, rng, step, weights, judge)
        optimiser.zero_grad()
        parts["total"].backward()
        nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimiser.step()
        step += 1
        rate = (step - first_step) / max(time.time() - started, 1e-9)
        bar.update(1)
        bar.set_postfix(loss=f"{float(parts['total'].detach()):.3f}", its=f"{rate:.2f}")
        if tb:
            for k, v in parts.items():
                tb.add_scalar(f"train/{k}", float(v.detach()), step)
            tb.add_scalar("train/lr", lr, step)
            tb.add_scalar("train/iterations_per_s", rate, step)
        if step % args.val_every == 0 or step == stop_at:
            val = validate(model, losses, val_batches, judge)
            # beside the held-out songs' loss, how well it knows its own: a memoriser's gap
            val["training_songs_feat"] = validate(model, losses, seen_batches)["feat"]
            if tb:
                for k, v in val.items():
                    tb.add_scalar(f"val/{k}", v, step)
            bar.write(f"step {step} val " + " ".join(f"{k} {v:.4f}" for k, v in val.items()))
            if best is None or val["pos"] < best["pos"]:
                best = {**val, "step": step}
        if step % args.save_every == 0 or step == stop_at:
            save_checkpoint(
                args.checkpoint, model, optimiser, step, args, stats, poses, best, stages
            )
    bar.close()
    if step >= last and args.stage and args.stage not in stages:
        stages.append(args.stage)
    save_checkpoint(args.checkpoint, model, optimiser, step, args, stats, poses, best, stages)
    elapsed = time.time() - started
    print(
        f"{step - first_step} steps in {elapsed:.0f} s "
        f"({(step - first_step) / max(elapsed, 1e-9):.2f} it/s); checkpoint {args.checkpoint}"
    )


# --------------------------------------------------------------------------- generation


@torch.no_grad()
def generate(
    model: DanceNet,
    stats: DF.DanceStats,
    audio_raw: np.ndarray,
    genre: np.ndarray,
    start: np.ndarray,
) -> np.ndarray:
    """Raw poses ``(F, M)`` for raw audio input ``(F, A)``, genre vector ``(G,)`` and a raw
    start pose ``(M,)`` (frame 0), free-running (torch; the service does this in ORT, and
    ``training.eval_dance`` judges the service's result)."""
    model.eval()
    code, _ = model.encode_audio(torch.from_numpy(stats.normalize_audio(audio_raw))[None])
    g = torch.from_numpy(np.asarray(genre, np.float32))[None]
    prev = torch.from_numpy(stats.normalize_motion(start))[None]
    state = model.init_state(1)
    out = [prev]
    for t in range(1, len(audio_raw)):
        prev, *state = model.step(code[:, t], g, prev, *state)
        out.append(prev)
    return stats.denormalize_motion(torch.cat(out).numpy())


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    train(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

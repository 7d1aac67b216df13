"""Music to dance (jacob2019, made to work): data windows, network, losses, training loop.

    python -m training.dance [--max-steps N] [--minutes M] [--resume]
    python -m training.eval_dance              # held-out songs, through the shipped engine

Network (per frame at 30 fps): the song's features (``motion.dance_features.song_features``:
log-mel, the thesis's spectral summary, onset, beat phase) -> two fully connected layers ->
audio code; [code, genre embedding, previous pose] -> two stacked LSTM cells (dropout
between) -> the next pose (``motion.dance_features`` encoding: 6D rotations with the hips
relative to the facing frame, root velocity and turning in the facing frame, hips height,
foot contacts). The genre is given (one-hot) or predicted from the music by a classifier
head on the time-averaged audio code, whose probabilities then stand in for the one-hot.

Training: windows of ``--window`` frames from the Dance with Melody dances (retimed onto
their songs' clocks as ``training/dance_alignment.json`` says; beat phase only where the
alignment was verified, "unknown" elsewhere) and, with probability ``--cmu-share``, CMU
salsa / Indian / modern dances with silent audio (a motion prior for the network). Auto-
conditioning (Zhou et al. 2018): ground-truth stretches of ``--gt-frames`` alternate with
self-fed stretches whose length ramps up to ``--cond-frames``, so long generation neither
freezes nor drifts. Losses: rotation/root features, forward-kinematics positions (root-local,
leg lengths), Laban effort (angular-velocity energy per window, log ratio), foot skating
under ground-truth contacts, genre cross-entropy. Whole songs are held out by take.

Writes ``checkpoints/dance.pt`` (weights, step, config and the feature statistics: what an
export needs) and the optimiser beside it in ``dance.pt.state`` (for ``--resume``, never
committed), TensorBoard scalars in ``runs/dance``; ``MOTION_SMOKE=1`` stops after a few steps.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from motion import canonical as C
from motion import dance_features as DF
from motion import kinematics as K
from training import fk as TFK

REPO = Path(__file__).resolve().parent.parent
CHECKPOINT = REPO / "checkpoints" / "dance.pt"
RUNS = REPO / "runs" / "dance"
PREPARED_VERSION = "1"
VAL_TAKES = ("DANCE_C_8", "DANCE_R_5", "DANCE_W_26", "DANCE_W_8")
"""Held-out songs: one cha-cha, one rumba and one waltz with verified alignment, one waltz
whose tempo needed correcting (tango has one dance only: it stays in training)."""

WEIGHTS = {"feat": 1.0, "pos": 4.0, "effort": 0.2, "skate": 0.05, "genre": 0.1}


# --------------------------------------------------------------------------- data


@dataclass
class Sequence:
    """One dance as network inputs: raw ``audio (F, AUDIO_CHANNELS)`` and ``motion (F,
    MOTION_CHANNELS)`` at 30 fps on the song's clock, genre index, whether it has music and
    whether its beat phase is trusted."""

    name: str
    genre: int
    audio: np.ndarray
    motion: np.ndarray
    has_music: bool
    trusted: bool

    @property
    def frames(self) -> int:
        return len(self.motion)


def silent_audio(frames: int) -> np.ndarray:
    """Audio input ``(frames, AUDIO_CHANNELS)`` of silence (beat unknown)."""
    row = DF.song_features(np.zeros(2205, np.float32), 22050, 1)[0]
    return DF.drop_beats(np.repeat(row[None], frames, axis=0))


def retime(motion, rate: float):
    """``motion`` (30 fps, motion clock) resampled onto the song's clock: frame ``j`` shows
    motion time ``j / 30 / rate``."""
    count = int(np.floor((motion.num_frames - 1) * rate)) + 1
    return K.resample_at(motion, np.arange(count) / rate, motion.fps)


def _prepare_dwm(clip, alignment, root: Path) -> Sequence:
    from motion import audio_decode
    from training.dance_alignment import analyse_music

    motion = retime(clip.motion, alignment.rate)
    folder = root / Path(clip.extra["audio"]).parent
    music = analyse_music(folder)
    samples, sr = audio_decode.decode(folder / "audio.mp3")
    x = DF.song_features(
        samples,
        sr,
        motion.num_frames,
        offset=alignment.offset,
        beats=music["beats"],
        tempo=float(music["tempo"]),
    )
    if not alignment.trusted:
        x = DF.drop_beats(x)
    return Sequence(
        clip.name,
        DF.genre_index(clip.genre),
        x,
        DF.encode(motion).features,
        True,
        alignment.trusted,
    )


def prepare(log=print) -> list[Sequence]:
    """Every training/validation sequence, cached in the data cache (rebuilt when the clips,
    the alignment table or :data:`PREPARED_VERSION` change)."""
    from training import dance_alignment as DA
    from training.data import cache_dir, data_dir, load_cmu_dance, load_dance_with_melody

    table = DA.load_table()
    dwm, cmu = load_dance_with_melody(), load_cmu_dance()
    key = hashlib.sha256(
        json.dumps(
            [PREPARED_VERSION, table["dances"], [(c.name, c.num_frames) for c in dwm + cmu]],
            sort_keys=True,
        ).encode()
    ).hexdigest()[:16]
    path = cache_dir() / f"dance_prepared_{key}.npz"
    if path.exists():
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            return [
                Sequence(m["name"], m["genre"], z[f"a{i}"], z[f"m{i}"], m["music"], m["trusted"])
                for i, m in enumerate(meta)
            ]
    seqs = []
    for clip in dwm:
        alignment = DA.alignment_for(clip.name, table)
        if alignment is None:
            log(f"{clip.name}: not in the alignment table, skipped")
            continue
        seqs.append(_prepare_dwm(clip, alignment, data_dir()))
        log(f"prepared {clip.name} ({alignment.verdict}, rate {alignment.rate:.4f})")
    for clip in cmu:
        if clip.genre not in DF.GENRES:
            continue
        motion = DF.encode(clip.motion).features
        seqs.append(
            Sequence(
                clip.name, DF.genre_index(clip.genre), silent_audio(len(motion)), motion,
                False, False,
            )
        )  # fmt: skip
    arrays = {}
    for i, s in enumerate(seqs):
        arrays[f"a{i}"], arrays[f"m{i}"] = s.audio, s.motion
    meta = [
        {"name": s.name, "genre": s.genre, "music": s.has_music, "trusted": s.trusted} for s in seqs
    ]
    np.savez_compressed(path, meta=np.array(json.dumps(meta)), **arrays)
    return seqs


def split(seqs: list[Sequence], val_takes=VAL_TAKES) -> tuple[list[Sequence], list[Sequence]]:
    """Train and validation sequences by whole song."""
    return [s for s in seqs if s.name not in val_takes], [s for s in seqs if s.name in val_takes]


def start_poses(seqs: list[Sequence], count: int = 64, seed: int = 0) -> np.ndarray:
    """Raw motion frames ``(count, MOTION_CHANNELS)`` spread over the training dances with
    music: the service's seeded starting poses."""
    rng = np.random.default_rng(seed)
    pool = [s for s in seqs if s.has_music]
    picks = []
    for i in range(count):
        s = pool[i % len(pool)]
        picks.append(s.motion[rng.integers(0, s.frames)])
    poses = np.stack(picks).astype(np.float32)
    poses[:, DF.VELOCITY] = 0.0
    poses[:, DF.TURN] = 0.0
    return poses


class WindowSampler:
    """Random windows ``(B, T, ...)`` of normalised training sequences."""

    def __init__(self, seqs, stats: DF.DanceStats, window: int, cmu_share: float, seed: int):
        self.window = window
        self.rng = np.random.default_rng(seed)
        self.music = [s for s in seqs if s.has_music and s.frames > window]
        self.silent = [s for s in seqs if not s.has_music and s.frames > window]
        self.cmu_share = cmu_share if self.silent else 0.0
        self.audio = {id(s): stats.normalize_audio(s.audio) for s in self.music + self.silent}
        self.motion = {id(s): stats.normalize_motion(s.motion) for s in self.music + self.silent}
        self.trusted_index = {id(s): s.trusted for s in self.music}

    def _pick(self, pool):
        weights = np.array([s.frames - self.window for s in pool], dtype=np.float64)
        return pool[self.rng.choice(len(pool), p=weights / weights.sum())]

    def batch(self, size: int, beat_dropout: float = 0.1):
        audio, motion, genre, music = [], [], [], []
        for _ in range(size):
            silent = self.rng.random() < self.cmu_share
            s = self._pick(self.silent if silent else self.music)
            t0 = int(self.rng.integers(0, s.frames - self.window))
            a = self.audio[id(s)][t0 : t0 + self.window].copy()
            if s.has_music and s.trusted and self.rng.random() < beat_dropout:
                a[:, DF.BEAT_COLUMNS] = 0.0
            audio.append(a)
            motion.append(self.motion[id(s)][t0 : t0 + self.window])
            genre.append(s.genre)
            music.append(s.has_music)
        return (
            torch.from_numpy(np.stack(audio)),
            torch.from_numpy(np.stack(motion)),
            torch.tensor(genre),
            torch.tensor(music),
        )


# --------------------------------------------------------------------------- network


@dataclass
class Config:
    hidden: int = 256
    code: int = 128
    audio_hidden: int = 256
    genre_dim: int = 16
    dropout: float = 0.25


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

    def encode_audio(self, audio: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        code = self.audio(audio)
        return code, self.classifier(code.mean(dim=1))

    def init_state(self, batch: int) -> tuple[torch.Tensor, ...]:
        z = torch.zeros(batch, self.config.hidden)
        return z, z, z, z

    def step(self, code, genre, prev, h1, c1, h2, c2):
        x = torch.cat([code, self.genre(genre), prev], dim=-1)
        h1, c1 = self.cell1(x, (h1, c1))
        h2, c2 = self.cell2(self.drop(h1), (h2, c2))
        return self.out(h2), h1, c1, h2, c2

    def rollout(
        self, code, genre, motion, gt_mask: torch.Tensor | None = None, warm: int = 0
    ) -> torch.Tensor:
        """Poses ``(B, T - 1, M)`` for frames 1.. of ``motion (B, T, M)``: frame 0 is given;
        each later frame is fed back its own prediction, or the ground truth where
        ``gt_mask (T,)`` is true (and for the first ``warm`` frames)."""
        state = self.init_state(motion.shape[0])
        prev = motion[:, 0]
        outs = []
        for t in range(1, motion.shape[1]):
            pose, *state = self.step(code[:, t], genre, prev, *state)
            outs.append(pose)
            use_gt = t < warm or (gt_mask is not None and bool(gt_mask[t]))
            prev = motion[:, t] if use_gt else pose
        return torch.stack(outs, dim=1)


def ac_mask(frames: int, gt: int, cond: int, rng: np.random.Generator) -> torch.Tensor:
    """``(frames,)`` bool: ground-truth stretches of ``gt`` frames alternating with self-fed
    stretches of ``cond`` frames, at a random phase."""
    period = gt + cond
    phase = int(rng.integers(0, period))
    return torch.from_numpy(((np.arange(frames) + phase) % period) < gt)


# --------------------------------------------------------------------------- losses


class Losses(nn.Module):
    """Feature, FK position, Laban effort and foot skating losses on standardised poses."""

    def __init__(self, stats: DF.DanceStats) -> None:
        super().__init__()
        self.register_buffer("mean", torch.from_numpy(stats.motion_mean))
        self.register_buffer("std", torch.from_numpy(stats.motion_std))
        self.register_buffer(
            "offsets", torch.tensor(C.OFFSETS[DF.BODY] / DF.LEG, dtype=torch.float32)
        )
        self.parents = [-1] + [int(p) - 1 for p in C.PARENTS[DF.BODY[1:]]]
        feet = [int(np.flatnonzero(DF.BODY == j)[0]) for j in DF.FOOT_JOINTS]
        self.feet = feet

    def raw(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.std + self.mean

    def kinematics(self, raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Local matrices ``(..., 21, 3, 3)`` and root-local positions ``(..., 21, 3)``."""
        r6 = raw[..., DF.ROTATIONS].reshape(raw.shape[:-1] + (len(DF.BODY), 6))
        lmat = TFK.matrix_from_6d(r6)
        lpos = self.offsets.expand(raw.shape[:-1] + (len(DF.BODY), 3))
        h = raw[..., DF.HEIGHT]
        root = torch.stack([torch.zeros_like(h), h, torch.zeros_like(h)], dim=-1)
        lpos = torch.cat([root.unsqueeze(-2), lpos[..., 1:, :]], dim=-2)
        return lmat, TFK.fk(lmat, lpos, self.parents)[1]

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> dict[str, torch.Tensor]:
        """``pred``, ``target`` ``(B, T, M)`` standardised -> named scalar losses."""
        out = {"feat": ((pred - target) ** 2).mean()}
        rp, rt = self.raw(pred), self.raw(target)
        mp, pp = self.kinematics(rp)
        mt, pt = self.kinematics(rt)
        out["pos"] = ((pp - pt) ** 2).sum(-1).mean()
        # Laban effort: angular-velocity energy (frame-to-frame rotation change), per window
        ep = ((mp[:, 1:] - mp[:, :-1]) ** 2).sum((-1, -2)).mean((1, 2)) * DF.FPS**2
        et = ((mt[:, 1:] - mt[:, :-1]) ** 2).sum((-1, -2)).mean((1, 2)) * DF.FPS**2
        out["effort"] = (torch.log(ep + 1e-3) - torch.log(et + 1e-3)).abs().mean()
        # foot skating: world speed on the floor of the predicted feet where the target is planted
        fp = pp[..., self.feet, :]
        vel = (fp[:, 1:] - fp[:, :-1]) * DF.FPS
        root_v = rp[:, 1:, DF.VELOCITY]
        turn = rp[:, 1:, DF.TURN].unsqueeze(-1)
        vx = vel[..., 0] + root_v[..., 0:1] + turn * fp[:, 1:, :, 2]
        vz = vel[..., 2] + root_v[..., 1:2] - turn * fp[:, 1:, :, 0]
        planted = (rt[:, 1:, DF.CONTACTS] > 0.5).float()
        out["skate"] = (planted * (vx**2 + vz**2)).sum() / planted.sum().clamp_min(1.0)
        return out


# --------------------------------------------------------------------------- training


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=20000, help="schedule length (lr decay)")
    p.add_argument("--max-steps", type=int, default=None, help="stop after this many steps")
    p.add_argument("--minutes", type=float, default=None, help="stop after this wall time")
    p.add_argument("--resume", action="store_true", help=f"continue from {CHECKPOINT.name}")
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
        p.add_argument(f"--w-{name}", type=float, default=value, help=f"{name} loss weight")
    p.add_argument("--val-every", type=int, default=500)
    p.add_argument("--save-every", type=int, default=500)
    p.add_argument("--checkpoint", type=Path, default=CHECKPOINT)
    p.add_argument("--log-dir", type=Path, default=RUNS)
    p.add_argument("--threads", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if os.environ.get("MOTION_SMOKE"):
        args.max_steps = min(args.max_steps or 3, 3)
    return args


def save_checkpoint(path: Path, model, optimiser, step, args, stats, poses, best) -> None:
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


def train_step(model, losses, batch, args, rng, step, weights) -> dict[str, torch.Tensor]:
    audio, motion, genre, music = batch
    code, logits = model.encode_audio(audio)
    onehot = nn.functional.one_hot(genre, len(DF.GENRES)).float()
    cond_vec = onehot
    if args.predicted_genre > 0:
        probs = torch.softmax(logits.detach(), dim=-1)
        predicted = torch.zeros_like(onehot)
        predicted[:, : len(DF.MUSIC_GENRES)] = probs
        use = music & (torch.rand(len(genre)) < args.predicted_genre)
        cond_vec = torch.where(use[:, None], predicted, onehot)
    cond = max(1, min(args.cond_frames, 1 + step * args.cond_frames // max(args.cond_ramp, 1)))
    mask = ac_mask(motion.shape[1], args.gt_frames, cond, rng)
    pred = model.rollout(code, cond_vec, motion, mask, warm=args.warm)
    parts = losses(pred, motion[:, 1:])
    if music.any():
        parts["genre"] = nn.functional.cross_entropy(logits[music], genre[music])
    else:
        parts["genre"] = torch.zeros(())
    parts["total"] = sum(weights[k] * parts[k] for k in weights)
    return parts


@torch.no_grad()
def validate(model, losses, val_batches) -> dict[str, float]:
    """Mean losses over fixed validation windows, free-running after the warm-up frames."""
    model.eval()
    totals: dict[str, float] = {}
    correct = count = 0
    for audio, motion, genre, music in val_batches:
        code, logits = model.encode_audio(audio)
        onehot = nn.functional.one_hot(genre, len(DF.GENRES)).float()
        pred = model.rollout(code, onehot, motion, None, warm=8)
        for k, v in losses(pred, motion[:, 1:]).items():
            totals[k] = totals.get(k, 0.0) + float(v) / len(val_batches)
        correct += int((logits[music].argmax(-1) == genre[music]).sum())
        count += int(music.sum())
    totals["genre_acc"] = correct / max(count, 1)
    model.train()
    return totals


def train(args: argparse.Namespace) -> None:
    from tqdm import tqdm

    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    seqs = prepare()
    train_seqs, val_seqs = split(seqs)
    weights = {k: getattr(args, f"w_{k}") for k in WEIGHTS}
    if args.resume and args.checkpoint.exists():
        model, stats, ckpt = load_checkpoint(args.checkpoint)
        model.train()
        poses, step, best = ckpt["start_poses"], int(ckpt["step"]), ckpt.get("best_val")
    else:
        stats = DF.DanceStats.fit([s.audio for s in train_seqs if s.has_music],
                                  [s.motion for s in train_seqs])  # fmt: skip
        model, poses, step, best, ckpt = DanceNet(Config(hidden=args.hidden)), None, 0, None, None
        poses = start_poses(train_seqs)
    losses = Losses(stats)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    if ckpt is not None and optimiser_path(args.checkpoint).exists():
        optimiser.load_state_dict(torch.load(optimiser_path(args.checkpoint), weights_only=False))
    sampler = WindowSampler(train_seqs, stats, args.window, args.cmu_share, args.seed + step)
    val_sampler = WindowSampler(val_seqs, stats, args.window, 0.0, 1234)
    val_batches = [val_sampler.batch(16, beat_dropout=0.0) for _ in range(4)]
    tb = None
    try:
        from torch.utils.tensorboard import SummaryWriter

        tb = SummaryWriter(str(args.log_dir))
    except ImportError:  # pragma: no cover
        pass
    total_steps = args.steps
    stop_at = step + args.max_steps if args.max_steps else total_steps
    deadline = time.time() + 60 * args.minutes if args.minutes else math.inf
    model.train()
    bar = tqdm(total=stop_at - step, desc="dance", unit="it")
    started, first_step = time.time(), step
    while step < stop_at and time.time() < deadline:
        lr = args.lr * 0.5 * (1 + math.cos(math.pi * min(step / total_steps, 1.0)))
        for group in optimiser.param_groups:
            group["lr"] = lr
        parts = train_step(model, losses, sampler.batch(args.batch), args, rng, step, weights)
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
            val = validate(model, losses, val_batches)
            if tb:
                for k, v in val.items():
                    tb.add_scalar(f"val/{k}", v, step)
            bar.write(f"step {step} val " + " ".join(f"{k} {v:.4f}" for k, v in val.items()))
            if best is None or val["pos"] < best["pos"]:
                best = {**val, "step": step}
        if step % args.save_every == 0 or step == stop_at:
            save_checkpoint(args.checkpoint, model, optimiser, step, args, stats, poses, best)
    bar.close()
    save_checkpoint(args.checkpoint, model, optimiser, step, args, stats, poses, best)
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

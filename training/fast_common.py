"""What the fast style networks' training scripts share (holden2017): data as encoded
clips, window sampling, the two networks and the bone-length loss.

Networks read and write standardised features ``(batch, time, CHANNELS)``
(``motion.fast_features``); inside they work on ``(batch, channels, time)``.

- :class:`Autoencoder`: the loss network. Encoder ``ReLU(maxpool2(conv25(x)))`` with
  ``HIDDEN`` units, decoder ``conv25(depool2(h) - b0)`` (nearest-neighbour depooling:
  each pooled value repeated twice), as the paper's equations (1) and (2).
- :class:`StyleNet`: the transformation network, three width-25 convolutions with
  ReLU between (128 units in the paper), its output added to its input (a residual
  connection, last layer zero-initialised: training starts from the identity, which
  converges in the few minutes per style this project's CPUs allow).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from motion import fast_features as FF

REPO = Path(__file__).resolve().parent.parent
CHECKPOINTS = REPO / "checkpoints" / "fast"
RUNS = REPO / "runs" / "fast"
STATS_PATH = CHECKPOINTS / "stats.npz"
SPLIT_PATH = CHECKPOINTS / "split.json"

WIDTH = 25  # temporal filter width (paper)
HIDDEN = 256  # autoencoder hidden units (paper)
STYLE_HIDDEN = 64  # transformation network units (paper: 128; halved to keep 19 styles small)
WINDOW = 120  # frames: the paper's 240 frames at 60 fps is 4 s, 120 frames at our 30 fps
SPLIT_SEED = 0
VAL_FRACTION = 0.15


def smoke() -> bool:
    """``MOTION_SMOKE=1``: a few steps only (tests)."""
    return os.environ.get("MOTION_SMOKE", "") not in ("", "0")


# --------------------------------------------------------------------------- data


@dataclass
class EncodedClip:
    name: str
    dataset: str
    take: str
    style: str | None
    content: str | None
    features: np.ndarray  # (F, CHANNELS) raw


def encode_clips(clips) -> list[EncodedClip]:
    return [
        EncodedClip(c.name, c.dataset, c.take, c.style, c.content, FF.encode(c.motion).features)
        for c in clips
    ]


def load_encoded(cache: Path | None = None) -> tuple[list[EncodedClip], list[EncodedClip]]:
    """Every canonical clip of the shared data, encoded: ``(bandai, others)`` where
    ``others`` are CMU dance and Dance with Melody. Cached as ``cache/fast_features.npz``."""
    from training import data

    cache = cache or data.cache_dir() / "fast_features.npz"
    if cache.exists():
        with np.load(cache, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
            x = z["features"]
        clips = [
            EncodedClip(features=x[a:b], **m)
            for m, a, b in zip(meta, bounds[:-1], bounds[1:], strict=True)
        ]
    else:
        clips = encode_clips(data.load_bandai())
        clips += encode_clips(data.load_cmu_dance())
        clips += encode_clips(data.load_dance_with_melody())
        meta = [
            {k: getattr(c, k) for k in ("name", "dataset", "take", "style", "content")}
            for c in clips
        ]
        tmp = cache.with_suffix(".tmp.npz")
        np.savez_compressed(
            tmp,
            meta=np.array(json.dumps(meta)),
            lengths=np.array([len(c.features) for c in clips]),
            features=np.concatenate([c.features for c in clips]),
        )
        os.replace(tmp, cache)
    bandai = [c for c in clips if c.dataset.startswith("dataset-")]
    others = [c for c in clips if not c.dataset.startswith("dataset-")]
    return bandai, others


def split(clips: list[EncodedClip]) -> tuple[list[EncodedClip], list[EncodedClip]]:
    """Train/validation by take (``training.data.split_by_take``, stratified by style)."""
    from training.data import split_by_take

    return split_by_take(clips, VAL_FRACTION, seed=SPLIT_SEED, stratify="style")


def save_split(val: list[EncodedClip], path: Path = SPLIT_PATH) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "seed": SPLIT_SEED,
        "val_fraction": VAL_FRACTION,
        "stratify": "style",
        "validation_takes": sorted({c.take for c in val}),
    }
    path.write_text(json.dumps(doc, indent=1))


def sample_windows(
    clips: list[EncodedClip], n: int, length: int, rng: np.random.Generator
) -> np.ndarray:
    """``n`` random windows ``(n, length, CHANNELS)`` raw; clips are drawn in proportion to
    their frames; shorter clips are padded with their first and last frames (paper)."""
    sizes = np.array([len(c.features) for c in clips], dtype=np.float64)
    picks = rng.choice(len(clips), size=n, p=sizes / sizes.sum())
    out = np.empty((n, length, FF.CHANNELS), dtype=np.float32)
    for i, k in enumerate(picks):
        out[i] = window_of(clips[k].features, length, rng)
    return out


def window_of(x: np.ndarray, length: int, rng: np.random.Generator) -> np.ndarray:
    if len(x) >= length:
        start = int(rng.integers(0, len(x) - length + 1))
        return x[start : start + length]
    before = int(rng.integers(0, length - len(x) + 1))
    return np.pad(x, ((before, length - len(x) - before), (0, 0)), mode="edge")


# --------------------------------------------------------------------------- networks


class Autoencoder(nn.Module):
    """The loss network (paper eq. 1-2); ``forward`` is the manifold projection."""

    def __init__(self, channels: int = FF.CHANNELS, hidden: int = HIDDEN, width: int = WIDTH):
        super().__init__()
        self.conv = nn.Conv1d(channels, hidden, width, padding=width // 2)
        self.deconv = nn.Conv1d(hidden, channels, width, padding=width // 2)
        self.dropout = nn.Dropout(0.2)

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Hidden units ``(B, hidden, ceil(T/2))`` from features ``(B, T, C)``."""
        h = self.conv(self.dropout(x.transpose(1, 2)))
        # one frame of -inf on the right makes floor pooling pool an odd last frame alone
        # (ceil mode without a shape-dependent branch, so exports keep time symbolic)
        h = F.pad(h, (0, 1), value=-1e9)
        return F.relu(F.max_pool1d(h, 2))

    def decode(self, h: torch.Tensor, frames: int) -> torch.Tensor:
        """Features ``(B, frames, C)`` from hidden units ``(B, hidden, ceil(frames/2))``."""
        up = h.unsqueeze(-1).expand(-1, -1, -1, 2).flatten(2)[..., :frames]
        up = up - self.conv.bias[None, :, None]
        return self.deconv(up).transpose(1, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decode(self.encode(x), x.shape[1])


class Projection(nn.Module):
    """Export wrapper: ``motion (B, T, C)`` -> projected ``motion (B, T, C)``."""

    def __init__(self, ae: Autoencoder):
        super().__init__()
        self.ae = ae

    def forward(self, motion: torch.Tensor) -> torch.Tensor:
        return self.ae(motion)


class StyleNet(nn.Module):
    """The transformation network: ``x + conv(relu(conv(relu(conv(x)))))`` over time."""

    def __init__(self, channels: int = FF.CHANNELS, hidden: int = STYLE_HIDDEN, width: int = WIDTH):
        super().__init__()
        pad = width // 2
        self.layers = nn.ModuleList(
            [
                nn.Conv1d(channels, hidden, width, padding=pad),
                nn.Conv1d(hidden, hidden, width, padding=pad),
                nn.Conv1d(hidden, channels, width, padding=pad),
            ]
        )
        nn.init.zeros_(self.layers[-1].weight)
        nn.init.zeros_(self.layers[-1].bias)

    def forward(self, motion: torch.Tensor) -> torch.Tensor:
        h = motion.transpose(1, 2)
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i < len(self.layers) - 1:
                h = F.relu(h)
        return motion + h.transpose(1, 2)


def receptive_field() -> int:
    """Frames one output frame of style net + projection depends on (either side)."""
    return 3 * (WIDTH // 2) + 2 * (WIDTH // 2) * 2


# --------------------------------------------------------------------------- losses


class Physics(nn.Module):
    """Raw features from standardised ones, and the bone-length constraint on them."""

    def __init__(self, mean: np.ndarray, std: np.ndarray):
        super().__init__()
        self.register_buffer("mean", torch.tensor(mean))
        self.register_buffer("std", torch.tensor(std))
        child, parent, length = FF.bone_pairs()
        self.child, self.parent = child.tolist(), parent.tolist()
        self.register_buffer("length", torch.tensor(length))

    def raw(self, z: torch.Tensor) -> torch.Tensor:
        return z * self.std + self.mean

    def positions(self, raw: torch.Tensor) -> torch.Tensor:
        """Root-local joint positions ``(B, T, 21, 3)`` in leg lengths."""
        return raw[..., : FF.POSITION_CHANNELS].unflatten(-1, (-1, 3))

    def bone_loss(self, raw: torch.Tensor) -> torch.Tensor:
        """Paper eq. 8: squared bone-length errors, leg lengths."""
        p = self.positions(raw)
        lengths = (p[..., self.child, :] - p[..., self.parent, :]).norm(dim=-1)
        return ((lengths - self.length) ** 2).mean()


# --------------------------------------------------------------------------- logging


class Logger:
    """TensorBoard scalars (when available) and a plain-text log under ``runs/fast/<name>``."""

    def __init__(self, name: str, root: Path = RUNS):
        self.dir = root / name
        self.dir.mkdir(parents=True, exist_ok=True)
        self.text = open(self.dir / "log.txt", "a")  # noqa: SIM115
        try:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(self.dir))
        except Exception:  # tensorboard missing: text log only
            self.tb = None
        self.started = time.time()

    def scalars(self, step: int, values: dict[str, float]) -> None:
        if self.tb is not None:
            for key, value in values.items():
                self.tb.add_scalar(key, value, step)
        line = " ".join(f"{k}={v:.5g}" for k, v in values.items())
        self.text.write(f"{time.time() - self.started:8.1f}s step {step} {line}\n")
        self.text.flush()

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()
        self.text.close()

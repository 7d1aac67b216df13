"""What the fast style networks' training and export share: the network, its sizes, the
folders and the training log.

:class:`StyleNet` is one style's restyler, distilled from the translator: it reads what
the translator's restyler reads (``motion.features.restyler_input``: head, hands, feet and
toes about the hips, each about its mean over the clip, and how the body travels;
standardised, ``(batch, CONTROL_CHANNELS, time)``) and writes what it writes (every
joint's rotation and the hips' height, standardised, ``(batch, OUTPUT_CHANNELS, time)``),
for one style code baked in. A width-5 convolution, three residual dilated convolutions
(dilations 2, 4, 8; ReLU) and a 1x1 convolution out: 30 frames seen either side.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import torch
from torch import nn

from motion import features as Fe

REPO = Path(__file__).resolve().parent.parent
CHECKPOINTS = REPO / "checkpoints" / "fast"
RUNS = REPO / "runs" / "fast"

WIDTH = 5  # temporal filter width
DILATIONS = (2, 4, 8)
STYLE_HIDDEN = 192  # units
WINDOW = 120  # frames a training example spans (4 s at 30 fps)


def smoke() -> bool:
    """``MOTION_SMOKE=1``: a few steps only (tests)."""
    return os.environ.get("MOTION_SMOKE", "") not in ("", "0")


class StyleNet(nn.Module):
    """One style's restyler (module docstring)."""

    def __init__(self, hidden: int = STYLE_HIDDEN):
        super().__init__()
        pad = WIDTH // 2
        self.inp = nn.Conv1d(Fe.CONTROL_CHANNELS, hidden, WIDTH, padding=pad)
        self.blocks = nn.ModuleList(
            [nn.Conv1d(hidden, hidden, WIDTH, padding=pad * d, dilation=d) for d in DILATIONS]
        )
        self.out = nn.Conv1d(hidden, Fe.OUTPUT_CHANNELS, 1)

    def forward(self, control: torch.Tensor) -> torch.Tensor:
        h = torch.relu(self.inp(control))
        for block in self.blocks:
            h = h + torch.relu(block(h))
        return self.out(h)


def receptive_field() -> int:
    """Frames one output frame depends on, either side."""
    return (WIDTH // 2) * (1 + sum(DILATIONS))


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

"""The translator's networks: a style encoder for 3D clips and one for 2D keypoints, and a
restyler that rewrites a content clip's rotations for a style code.

Tensors are ``(B, C, T)`` (batch, channels, frames at 30 fps) of standardised
``motion.features`` channels. The restyler reads only what the content does with its
head, hands and feet about its hips, and how it travels
(``motion.features.restyler_input``), and writes every joint's rotation and the hips'
height: the rest of the pose, and the posture, come from the style code, so a performer's
own manner cannot carry into the output. The style code acts on every block through a
FiLM scale and shift. No layer normalises over time, so a frame depends only on the
frames within the receptive field around it, whatever the clip's length (the service runs
the restyler in overlapping windows of the length it trained on).

Exported as three ONNX graphs (``model_export/translator.py``): ``style3d``, ``style2d``
and ``restyler``, dynamic batch and time.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
import torch.nn.functional as F
from torch import nn

from motion import features as Fe

RESTYLER_IN = Fe.CONTROL_CHANNELS  # motion.features.restyler_input


@dataclass
class NetworkConfig:
    """Sizes of the networks (saved beside the weights)."""

    channels: int = 192
    dilations: list[int] = field(default_factory=lambda: [1, 2, 4, 8, 1, 2, 4, 8])
    kernel: int = 3
    style_dim: int = 64
    style_channels: list[int] = field(default_factory=lambda: [96, 128, 160])
    num_styles: int = 16

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def receptive_field(self) -> int:
        """Frames a restyled frame depends on (odd, centred on it)."""
        return 1 + 2 * (self.kernel // 2) * (2 + len(self.dilations) + sum(self.dilations))


class StyleEncoder(nn.Module):
    """``(B, C_in, T)`` -> style code ``(B, style_dim)``: strided convolutions, mean over time
    (every frame counts, so a longer clip gives a steadier code)."""

    def __init__(self, cfg: NetworkConfig, channels_in: int) -> None:
        super().__init__()
        chans = [channels_in, *cfg.style_channels]
        self.convs = nn.ModuleList(
            nn.Conv1d(a, b, 5, stride=1 if i == 0 else 2, padding=2)
            for i, (a, b) in enumerate(zip(chans[:-1], chans[1:], strict=True))
        )
        self.last = nn.Linear(chans[-1], cfg.style_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.convs:
            x = F.leaky_relu(layer(x), 0.2)
        return self.last(x.mean(dim=-1))


class Block(nn.Module):
    """Dilated convolution, per-frame layer norm, FiLM by the style, convolution, skip."""

    def __init__(self, channels: int, kernel: int, dilation: int) -> None:
        super().__init__()
        pad = dilation * (kernel // 2)
        self.conv1 = nn.Conv1d(channels, channels, kernel, padding=pad, dilation=dilation)
        self.conv2 = nn.Conv1d(channels, channels, kernel, padding=kernel // 2)

    def forward(self, x: torch.Tensor, scale: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
        h = self.conv1(F.leaky_relu(x, 0.2))
        h = frame_norm(h) * (1.0 + scale.unsqueeze(-1)) + shift.unsqueeze(-1)
        return x + self.conv2(F.leaky_relu(h, 0.2))


def frame_norm(x: torch.Tensor, eps: float = 1e-5) -> torch.Tensor:
    """``x (B, C, T)`` normalised over channels at each frame (no statistics over time)."""
    mean = x.mean(dim=1, keepdim=True)
    var = (x - mean).pow(2).mean(dim=1, keepdim=True)
    return (x - mean) / torch.sqrt(var + eps)


class Restyler(nn.Module):
    """Content control ``(B, RESTYLER_IN, T)`` and a style code ``(B, style_dim)`` ->
    standardised rotations ``(B, OUTPUT_CHANNELS, T)``."""

    def __init__(self, cfg: NetworkConfig) -> None:
        super().__init__()
        c = cfg.channels
        self.first = nn.Conv1d(RESTYLER_IN, c, cfg.kernel, padding=cfg.kernel // 2)
        self.blocks = nn.ModuleList(Block(c, cfg.kernel, d) for d in cfg.dilations)
        self.film = nn.Sequential(
            nn.Linear(cfg.style_dim, 256),
            nn.LeakyReLU(0.2),
            nn.Linear(256, 2 * c * len(cfg.dilations)),
        )
        self.last = nn.Conv1d(c, Fe.OUTPUT_CHANNELS, cfg.kernel, padding=cfg.kernel // 2)
        nn.init.zeros_(self.last.weight)  # starts at the mean pose
        nn.init.zeros_(self.last.bias)

    def forward(self, content: torch.Tensor, code: torch.Tensor) -> torch.Tensor:
        params = self.film(code).chunk(2 * len(self.blocks), dim=1)
        h = self.first(content)
        for i, block in enumerate(self.blocks):
            h = block(h, params[2 * i], params[2 * i + 1])
        return self.last(F.leaky_relu(h, 0.2))


class Translator(nn.Module):
    """The three exported networks together, and each named style's code (``named``,
    exported as the style table): training asks the style encoders to give a style's
    clips that code."""

    def __init__(self, cfg: NetworkConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.style3d = StyleEncoder(cfg, Fe.STYLE3D_CHANNELS)
        self.style2d = StyleEncoder(cfg, Fe.STYLE2D_CHANNELS)
        self.restyler = Restyler(cfg)
        self.named = nn.Embedding(cfg.num_styles, cfg.style_dim)


class Discriminator(nn.Module):
    """Is a window of motion a real performance of style k? ``(B, 2 * 63 + 1, T)`` positions
    relative to the hips, their velocities and the hips height -> scores, one head
    per style (a multi-task discriminator, as aberman2020's); training reads the head of
    each window's style."""

    def __init__(self, cfg: NetworkConfig, channels: tuple[int, ...] = (96, 128, 160)) -> None:
        super().__init__()
        chans = [2 * Fe.STYLE3D_CHANNELS + 1, *channels]
        self.convs = nn.ModuleList(
            nn.Conv1d(a, b, 4, stride=2, padding=1)
            for a, b in zip(chans[:-1], chans[1:], strict=True)
        )
        self.head = nn.Conv1d(chans[-1], cfg.num_styles, 1)

    def forward(self, x: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """Scores ``(B, T')`` of windows ``x`` for their styles ``(B,)``."""
        for layer in self.convs:
            x = F.leaky_relu(layer(x), 0.2)
        scores = self.head(x)
        return scores.gather(1, style[:, None, None].expand(-1, 1, scores.shape[-1]))[:, 0]


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())

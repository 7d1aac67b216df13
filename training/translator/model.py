"""The aberman2020 motion translator: content encoder, 3D and 2D style encoders, decoder with
AdaIN, and the multi-style discriminator.

Tensors are ``(B, C, T)`` (batch, channels, frames at 30 fps) of standardised
``motion.features`` channels. Written for ONNX export as four graphs (content encoder,
3D style encoder, 2D style encoder, decoder with its style MLP) with dynamic batch and
time: no parameter is assigned at run time (AdaIN scale and shift are computed from the
style code and passed along), pooling is ``amax``, no data-dependent Python control flow.

``STRIDE`` frames: every graph needs ``T`` to be a multiple of it (pad with
``motion.features.pad_frames`` or :func:`pad_time`, then crop the output back).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
import torch.nn.functional as F
from torch import nn

from motion import features as Fe

STRIDE = 4  # 2 ** max(content_down, style_down); the config checks it


@dataclass
class ModelConfig:
    """Sizes of the networks (saved with the weights)."""

    content_in: int = Fe.CONTENT_CHANNELS
    output: int = Fe.OUTPUT_CHANNELS
    style3d_in: int = Fe.STYLE3D_CHANNELS
    style2d_in: int = Fe.STYLE2D_CHANNELS
    num_styles: int = 19
    content_channels: list[int] = field(default_factory=lambda: [128, 160])
    content_resblocks: int = 1
    style_channels: list[int] = field(default_factory=lambda: [96, 128, 144])
    style_dim: int = 128
    mlp_hidden: int = 192
    decoder_resblocks: int = 2
    disc_channels: list[int] = field(default_factory=lambda: [96, 128, 160])
    num_contents: int = 0  # > 0: the discriminator also judges each content label
    kernel: int = 5
    keep_amplitude: bool = False  # every instance norm may learn to keep some of x's amplitude
    # > 0: the content code passes through this many channels (a linear squeeze and
    # unsqueeze), the paper's restricted content dimensionality against copying the style
    content_bottleneck: int = 0
    # > 1: each decoder residual convolution is a mix of this many kernels, weighted per
    # clip by the style code, so style can act on timing and shape, not only on AdaIN's
    # per-channel scale and shift (CondConv-style)
    style_kernels: int = 0

    @property
    def content_down(self) -> int:
        return len(self.content_channels) - 1

    @property
    def style_down(self) -> int:
        return len(self.style_channels) - 1

    def __post_init__(self) -> None:
        if 2 ** max(self.content_down, self.style_down, len(self.disc_channels) - 1) > STRIDE:
            raise ValueError(f"down-sampling exceeds STRIDE={STRIDE}")
        if self.style_kernels < 0 or self.style_kernels == 1:
            raise ValueError(f"style_kernels {self.style_kernels} must be 0 (none) or at least 2")
        if not 0 <= self.content_bottleneck <= self.content_channels[-1]:
            raise ValueError(
                f"content_bottleneck {self.content_bottleneck} must be 0 (none) or at most "
                f"the content code's {self.content_channels[-1]} channels"
            )

    def to_dict(self) -> dict:
        return asdict(self)


def pad_time(x: torch.Tensor, multiple: int = STRIDE) -> torch.Tensor:
    """``x (B, C, T)`` with its last frame repeated up to a multiple of ``multiple``."""
    extra = (-x.shape[-1]) % multiple
    return F.pad(x, (0, extra), mode="replicate") if extra else x


def conv(c_in: int, c_out: int, kernel: int, stride: int = 1) -> nn.Conv1d:
    """Same-length (or exactly ``T / stride``) convolution for even ``T``."""
    if stride == 1:
        return nn.Conv1d(c_in, c_out, kernel, padding=kernel // 2)
    return nn.Conv1d(c_in, c_out, 2 * stride, stride=stride, padding=stride // 2)


NORM_EPS = 1e-5  # F.instance_norm's
AMPLITUDE_FRAMES = 32  # about a second at 30 fps: the span a kept amplitude is measured over
MAX_LOG_AMPLITUDE = 3.0  # a span's amplitude counts up to e**3 times its channel's usual one
AMPLITUDE_PARAMETERS = (".keep", ".log_ref")  # the names' endings of what keep_amplitude adds
# the kernel mix's logits are its linear layer's output times this: Adam moves weights by
# about the learning rate whatever their scale, and at the rates that fine-tune a trained
# model (~4e-5) unscaled logits would take ~10^5 steps to mix at all
MIX_GAIN = 25.0


class Norm(nn.Module):
    """Instance norm over time. With ``keep_amplitude`` it may learn to hand some of the
    input's own amplitude on: ``instance_norm(x) * (sigma_t / ref) ** keep`` per channel,
    ``sigma_t`` the spread of ``x`` about its mean over about a second around frame t,
    ``keep = tanh(k)`` starting at 0 (plain instance norm), ``ref`` the channel's usual
    spread (see :func:`calibrate_amplitude`). Plain instance norm strips how far each
    channel moves, and for a wave or a raise that is the content. ``level``: the layer
    runs at ``30 / 2**level`` fps. Measured over a second rather than the whole input, so
    training windows and whole clips see the same spans."""

    def __init__(self, channels: int, keep_amplitude: bool, level: int = 0) -> None:
        super().__init__()
        self.keep = nn.Parameter(torch.zeros(channels)) if keep_amplitude else None
        self.log_ref = nn.Parameter(torch.zeros(channels)) if keep_amplitude else None
        self.span = (AMPLITUDE_FRAMES >> level) - 1  # odd, so it centres on the frame
        self.calibrating = False

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.instance_norm(x)
        if self.keep is None:
            return y
        centred = x - x.mean(dim=-1, keepdim=True)
        local_var = F.avg_pool1d(
            centred * centred, self.span, stride=1, padding=self.span // 2,
            count_include_pad=False,
        )  # fmt: skip
        log_sigma = 0.5 * torch.log(local_var + NORM_EPS)
        if self.calibrating:
            with torch.no_grad():
                self.log_ref.copy_(log_sigma.mean(dim=(0, 2)))
        ratio = (log_sigma - self.log_ref.unsqueeze(-1)).clamp(
            -MAX_LOG_AMPLITUDE, MAX_LOG_AMPLITUDE
        )
        return y * torch.exp(torch.tanh(self.keep).unsqueeze(-1) * ratio)


def adain(x: torch.Tensor, scale: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
    """``x * scale + shift`` for a normalised ``x (B, C, T)``; ``scale``/``shift (B, C)``."""
    return x * scale.unsqueeze(-1) + shift.unsqueeze(-1)


class ResBlock(nn.Module):
    """Two convolutions with instance norm and a skip (content encoder)."""

    def __init__(
        self, channels: int, kernel: int, keep_amplitude: bool = False, level: int = 0
    ) -> None:
        super().__init__()
        self.conv1 = conv(channels, channels, kernel)
        self.conv2 = conv(channels, channels, kernel)
        self.norm1 = Norm(channels, keep_amplitude, level)
        self.norm2 = Norm(channels, keep_amplitude, level)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.leaky_relu(self.norm1(self.conv1(x)), 0.2)
        return x + self.norm2(self.conv2(h))


class MixedConv(nn.Conv1d):
    """``kernels`` same-length convolutions in one, their outputs mixed per clip:
    ``sum_k mix[:, k] * conv_k(x)`` (a mix of kernels is the convolution by the mixed
    kernel). One convolution with ``kernels * channels`` outputs exports as plain ONNX."""

    def __init__(self, channels: int, kernel: int, kernels: int) -> None:
        super().__init__(channels, kernels * channels, kernel, padding=kernel // 2)
        self.kernels, self.channels = kernels, channels

    def forward(self, x: torch.Tensor, mix: torch.Tensor) -> torch.Tensor:
        y = super().forward(x).unflatten(1, (self.kernels, self.channels))
        return (y * mix[:, :, None, None]).sum(dim=1)


class AdaResBlock(nn.Module):
    """Two convolutions with AdaIN and a skip (decoder); ``params (B, 4 * C)``. With
    ``kernels`` > 1 each convolution is a :class:`MixedConv`, ``mix (B, 2, kernels)``."""

    def __init__(
        self,
        channels: int,
        kernel: int,
        keep_amplitude: bool = False,
        level: int = 0,
        kernels: int = 0,
    ) -> None:
        super().__init__()
        self.channels = channels

        def make_conv() -> nn.Conv1d:
            return (
                MixedConv(channels, kernel, kernels)
                if kernels
                else conv(channels, channels, kernel)
            )

        self.conv1, self.conv2 = make_conv(), make_conv()
        self.norm1 = Norm(channels, keep_amplitude, level)
        self.norm2 = Norm(channels, keep_amplitude, level)

    def forward(
        self, x: torch.Tensor, params: torch.Tensor, mix: torch.Tensor | None = None
    ) -> torch.Tensor:
        s1, b1, s2, b2 = params.split(self.channels, dim=1)
        h1 = self.conv1(x) if mix is None else self.conv1(x, mix[:, 0])
        h = F.leaky_relu(adain(self.norm1(h1), 1.0 + s1, b1), 0.2)
        h2 = self.conv2(h) if mix is None else self.conv2(h, mix[:, 1])
        return x + adain(self.norm2(h2), 1.0 + s2, b2)


class ContentEncoder(nn.Module):
    """``(B, content_in, T)`` -> content code ``(B, content_channels[-1], T / 2**content_down)``.

    Instance norm after every convolution strips the per-clip statistics (the style).
    """

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        chans = cfg.content_channels
        self.first = conv(cfg.content_in, chans[0], cfg.kernel)
        self.down = nn.ModuleList(
            conv(a, b, cfg.kernel, stride=2) for a, b in zip(chans[:-1], chans[1:], strict=True)
        )
        self.res = nn.ModuleList(
            ResBlock(chans[-1], cfg.kernel, cfg.keep_amplitude, cfg.content_down)
            for _ in range(cfg.content_resblocks)
        )
        self.norms = nn.ModuleList(
            Norm(c, cfg.keep_amplitude, level) for level, c in enumerate(chans)
        )
        self.bottleneck = (
            nn.Sequential(
                nn.Conv1d(chans[-1], cfg.content_bottleneck, 1),
                nn.Conv1d(cfg.content_bottleneck, chans[-1], 1),
            )
            if cfg.content_bottleneck
            else None
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.leaky_relu(self.norms[0](self.first(x)), 0.2)
        for layer, norm in zip(self.down, self.norms[1:], strict=True):
            h = F.leaky_relu(norm(layer(h)), 0.2)
        for block in self.res:
            h = block(h)
        return h if self.bottleneck is None else self.bottleneck(h)


class StyleEncoder(nn.Module):
    """``(B, C_in, T)`` -> style code ``(B, style_dim)``: convolutions, no normalisation (it
    would remove the style), global max pooling over time."""

    def __init__(self, cfg: ModelConfig, channels_in: int) -> None:
        super().__init__()
        chans = cfg.style_channels
        self.first = conv(channels_in, chans[0], cfg.kernel)
        self.down = nn.ModuleList(
            conv(a, b, cfg.kernel, stride=2) for a, b in zip(chans[:-1], chans[1:], strict=True)
        )
        self.last = nn.Conv1d(chans[-1], cfg.style_dim, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.leaky_relu(self.first(x), 0.2)
        for layer in self.down:
            h = F.leaky_relu(layer(h), 0.2)
        return self.last(h).amax(dim=-1)


class Decoder(nn.Module):
    """Content code ``(B, C_z, T')`` and style code ``(B, style_dim)`` -> standardised output
    rotations ``(B, output, T' * 2**content_down)``.

    An MLP maps the style code to every AdaIN layer's scale and shift (the scale is
    1 + its output, so a fresh network starts near plain instance norm).
    """

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        chans = cfg.content_channels[::-1]
        self.res = nn.ModuleList(
            AdaResBlock(
                chans[0], cfg.kernel, cfg.keep_amplitude, cfg.content_down, cfg.style_kernels
            )
            for _ in range(cfg.decoder_resblocks)
        )
        self.kernels = cfg.style_kernels
        if self.kernels:  # zero logits: every clip starts with an even mix
            self.mix = nn.Linear(cfg.style_dim, cfg.decoder_resblocks * 2 * self.kernels)
            nn.init.zeros_(self.mix.weight)
            nn.init.zeros_(self.mix.bias)
        self.up = nn.ModuleList(
            conv(a, b, cfg.kernel) for a, b in zip(chans[:-1], chans[1:], strict=True)
        )
        self.up_norms = nn.ModuleList(
            Norm(c, cfg.keep_amplitude, cfg.content_down - 1 - i) for i, c in enumerate(chans[1:])
        )
        self.last = conv(chans[-1], cfg.output, cfg.kernel)
        # AdaIN parameter count per layer, in the order forward consumes them
        self.param_sizes = [4 * chans[0]] * cfg.decoder_resblocks + [2 * c for c in chans[1:]]
        self.mlp = nn.Sequential(
            nn.Linear(cfg.style_dim, cfg.mlp_hidden),
            nn.LeakyReLU(0.2),
            nn.Linear(cfg.mlp_hidden, cfg.mlp_hidden),
            nn.LeakyReLU(0.2),
            nn.Linear(cfg.mlp_hidden, sum(self.param_sizes)),
        )

    def forward(self, content: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        params = self.mlp(style).split(self.param_sizes, dim=1)
        mixes: list[torch.Tensor | None] = [None] * len(self.res)
        if self.kernels:
            logits = (MIX_GAIN * self.mix(style)).unflatten(1, (len(self.res), 2, self.kernels))
            mixes = list(torch.softmax(logits, dim=-1).unbind(1))
        h = content
        for block, p, mix in zip(self.res, params, mixes, strict=False):
            h = block(h, p, mix)
        for layer, norm, p in zip(self.up, self.up_norms, params[len(self.res) :], strict=True):
            h = F.interpolate(h, scale_factor=2.0, mode="nearest")
            scale, shift = p.split(p.shape[1] // 2, dim=1)
            h = F.leaky_relu(adain(norm(layer(h)), 1.0 + scale, shift), 0.2)
        return self.last(h)


class Discriminator(nn.Module):
    """Multi-style discriminator (FUNIT's multi-task one): ``(B, C_in, T)`` -> per-style
    scores ``(B, num_styles, T / 2**n)`` and the last features ``(B, C, T / 2**n)``.
    With ``num_contents``, per-content scores follow the style ones (``num_styles + k``
    for content label k): is this a real performance of that action, in any style.

    Reads root-local positions and rotations (both standardised), so it judges poses and
    joint twists alike.
    """

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        chans = cfg.disc_channels
        self.first = conv(cfg.style3d_in + cfg.output, chans[0], cfg.kernel)
        self.down = nn.ModuleList(
            conv(a, b, cfg.kernel, stride=2) for a, b in zip(chans[:-1], chans[1:], strict=True)
        )
        self.head = nn.Conv1d(chans[-1], cfg.num_styles, 1)
        self.content_head = nn.Conv1d(chans[-1], cfg.num_contents, 1) if cfg.num_contents else None

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = F.leaky_relu(self.first(x), 0.2)
        for layer in self.down:
            h = F.leaky_relu(layer(h), 0.2)
        scores = self.head(h)
        if self.content_head is not None:
            scores = torch.cat([scores, self.content_head(h)], dim=1)
        return scores, h


class Translator(nn.Module):
    """The generator's parts together: ``content_encoder``, ``style3d``, ``style2d``,
    ``decoder`` (each one exportable graph)."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.content_encoder = ContentEncoder(cfg)
        self.style3d = StyleEncoder(cfg, cfg.style3d_in)
        self.style2d = StyleEncoder(cfg, cfg.style2d_in)
        self.decoder = Decoder(cfg)

    def forward(self, content: torch.Tensor, style3d: torch.Tensor) -> torch.Tensor:
        """Content ``(B, content_in, T)`` restyled by a 3D style clip ``(B, style3d_in, T2)``;
        both ``T`` multiples of ``STRIDE``."""
        return self.decoder(self.content_encoder(content), self.style3d(style3d))


@torch.no_grad()
def calibrate_amplitude(g: Translator, content: torch.Tensor, style3d: torch.Tensor) -> None:
    """Set every :class:`Norm`'s reference amplitude to its mean over a batch, so that
    learning to keep amplitude starts from no change in scale on average."""
    norms = [m for m in g.modules() if isinstance(m, Norm) and m.keep is not None]
    for m in norms:
        m.calibrating = True
    try:
        g(content, style3d)
    finally:
        for m in norms:
            m.calibrating = False


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())

"""The translator family (aberman2020): content clip + a style code from an example clip, a
video's 2D keypoints, a style name or a mix of names; numpy and onnxruntime only.

Graphs (``model_export/translator.py``): ``content_encoder``, ``style3d``, ``style2d`` and
``decoder``, all ``(batch, channels, time)``. Content runs through the content encoder and
the decoder in overlapping windows of the training length (``WINDOW``), blended: the
instance norms then see the span they learned on, and a frame depends on nearby frames
only. A style clip or video goes through its style encoder whole, padded in time to a
length bucket (a multiple of ``BUCKET`` frames, never shorter than the networks' receptive
field) by mirroring it at both ends, so onnxruntime sees few shapes and short clips are
padded rather than refused; the style codes of the named styles were computed the same way.

A transfer (paper section 3.4): encode the content; style code = own + strength x (target -
own), own being the content's 3D style code (strength 0 gives the content back, as the
network reconstructs it); decode; the content's root trajectory (``features.decode_motion``);
the hips raised or lowered so that the feet planted where the CONTENT's are stand on the
content's floor, then held there (``ik.pin_canonical_feet``, before the time warp, as the
paper does); then the time warp, to the power ``strength`` and clamped to
[``MIN_WARP``, ``MAX_WARP``]: for a style clip the paper's ratio of velocity factors (style
over content); for a named style or mix the style's speed against the other styles on the
same content (``model_export.translator.style_speeds``), over the speed of the named style
the content itself is in, if any (:meth:`TranslatorEngine.own_speed`). The ratio of a named
style's mean velocity factor to a clip's mixes up contents and slowed every run, sped up
every bow; a style's speed alone slowed an elderly clip restyled "elderly" to 0.54x.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion import contacts as CT
from motion import features as Fe
from motion import ik
from motion.keypoints import Keypoints2D
from motion.skeleton import Motion
from service.engines import register_engine
from service.engines.base import Engine
from service.errors import NotFound, ServiceError
from service.metrics import StageTimer

BUCKET = 64  # frames: padded lengths are multiples of this
MIN_WARP, MAX_WARP = 0.5, 2.0  # time warp factors are clamped to this range
NEAREST = 5  # named styles listed by nearest()
# Gaussian sigma (frames at 30 fps) on the decoder's rotations: it adds frame-to-frame
# jitter real motion lacks (joint jerk 4.3x the content's on the CMU walk; hips on standing
# Bandai clips turning 41 deg/s vs 9 real), which also slid the feet. On the held-out
# evaluation sigma 2 lowered foot sliding from 10.0 to 8.5 cm/s (real: 7.6) and left style
# and content recognition as they were (12.6 -> 13.3%, 49.0 -> 49.1%). Measured when whole
# clips ran at once; with windows the jitter is 2.9x the walk's (0.8x smoothed), and sigma
# 1 instead of 2 changes recognition by under a point.
OUTPUT_SMOOTHING = 2.0
# Codes from a clip or a video are scaled down to this multiple of the largest named style
# code's norm: Bandai clips' own codes reach 1.2x it, and the decoder, which never saw
# larger codes, then throws the body about. Real-video walks code at 0.4-0.6x; a video of
# someone collapsing at 2x.
CODE_NORM_LIMIT = 1.25
# A clip is in a named style when its own style code lies within SAME_STYLE_NEAR x the
# smallest distance between two named codes of that style's code; beyond SAME_STYLE_FAR x it
# is in none (fading between), and a named target's speed then stands alone. On 0.1.71412
# (smallest distance 6.75) the 51 held-out Bandai takes lie 0.9-4.2 from their nearest
# named code (median 1.9), which is their own style for all 26 within 2.0 and for 44 of the
# 51; the 9 CMU clips of ../shared/data/cmu-31 lie 3.5-6.0 from theirs (normal or proud).
SAME_STYLE_NEAR, SAME_STYLE_FAR = 0.3, 0.5
# The networks learned on windows of this many frames, and their instance norms take the
# statistics of the whole time axis: a whole clip at once normalises over a different
# span than training did. Content is therefore encoded and decoded in overlapping windows
# of this length, blended with Hann weights. On the 51 held-out Bandai takes, decoding
# each clip with its own style code gives joint positions 3.1 cm from the clip's (7.7 cm
# a whole clip at once; 4.1 cm with 48-frame windows, 5.5 cm with 64). A bundle names its
# training length (``extra.window``); those exported before it did trained on 32.
WINDOW = 32
WINDOW_HOP = WINDOW // 2
WINDOWS_PER_CALL = 256  # bounds the batch (memory) on long clips


class InvalidStyle(ServiceError):
    """A style field that is present but malformed (400 invalid-request)."""

    def __init__(self, detail: str, **ext: Any) -> None:
        super().__init__(400, "Invalid request", detail, slug="invalid-request", **ext)


@dataclass
class StyleCode:
    """A style code ``(S,)`` float32, the velocity factor of its source (None when unknown,
    e.g. a video: no time warp), what it came from, warnings for the client, and for named
    styles and mixes their ``speed`` against the other styles on the same content (the
    time warp then, instead of the ratio of velocity factors)."""

    code: np.ndarray
    velocity: float | None
    source: str
    warnings: list[str] = field(default_factory=list)
    speed: float | None = None


@dataclass
class Transfer:
    """A transfer's canonical result (30 fps, after clean-up and warp), the time-warp factor
    applied to it (the caller warps the original clip by the same factor) and warnings."""

    motion: Motion
    warp: float
    warnings: list[str] = field(default_factory=list)


def padded_length(frames: int, minimum: int = BUCKET) -> int:
    """The bucket a clip of ``frames`` frames runs at: a multiple of ``BUCKET``, >= ``minimum``."""
    return max(-(-frames // BUCKET) * BUCKET, -(-minimum // BUCKET) * BUCKET)


def pad_mirrored(x: np.ndarray, total: int) -> tuple[np.ndarray, int]:
    """``x (F, C)`` mirrored at both ends to ``total`` frames; returns it and the offset of
    frame 0 (crop ``[offset : offset + F]``)."""
    extra = total - len(x)
    before = extra // 2
    return np.pad(x, ((before, extra - before), (0, 0)), mode="symmetric"), before


def window_starts(frames: int, window: int = WINDOW, hop: int | None = None) -> list[int]:
    """Starts of the windows covering ``frames`` frames (``frames >= window``): every
    ``hop`` frames (half a window unless given), the last one flush with the end."""
    hop = hop or window // 2
    starts = list(range(0, frames - window + 1, hop))
    if starts[-1] != frames - window:
        starts.append(frames - window)
    return starts


def parse_mix(text: str) -> dict[str, float]:
    """The ``style_mix`` field: a JSON object name -> weight, weights finite and >= 0 with a
    positive sum; 400 otherwise. Weights are returned as given (normalised later)."""
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise InvalidStyle(f"'style_mix' is not JSON: {exc}", field="style_mix") from None
    if not isinstance(value, dict) or not value:
        raise InvalidStyle(
            "'style_mix' must be a non-empty JSON object of style name -> weight",
            field="style_mix",
        )
    mix: dict[str, float] = {}
    for name, weight in value.items():
        number = isinstance(weight, int | float) and not isinstance(weight, bool)
        if not number or not math.isfinite(weight) or weight < 0:
            raise InvalidStyle(
                f"'style_mix' weight of {name!r} must be a finite number >= 0, got {weight!r}",
                field="style_mix",
            )
        mix[name] = float(weight)
    if sum(mix.values()) <= 0:
        raise InvalidStyle("'style_mix' weights must have a positive sum", field="style_mix")
    return mix


class TranslatorEngine(Engine):
    family: ClassVar[str] = "translator"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": 2 * BUCKET, "code_time": BUCKET}

    def load_assets(self) -> None:
        extra = self.entry.extra
        arrays = self.load_npz(extra["stats"])
        kinds = [k.removesuffix("_mean") for k in arrays if k.endswith("_mean")]
        self.stats = Fe.FeatureStats(
            {k: arrays[f"{k}_mean"] for k in kinds}, {k: arrays[f"{k}_std"] for k in kinds}
        )
        table = self.load_npz(extra["styles_file"])
        self.style_names = [str(n) for n in table["names"]]
        self.codes = np.asarray(table["codes"], dtype=np.float32)
        self.clips = [int(c) for c in table["clips"]]
        self.velocity = [float(v) for v in table["velocity"]]
        # bundles exported before speeds existed warp named styles by velocity factors
        self.speed = [float(v) for v in table["speed"]] if "speed" in table else None
        self.index = {name: i for i, name in enumerate(self.style_names)}
        self.style_dim = int(self.codes.shape[1])
        gaps = np.linalg.norm(self.codes[:, None] - self.codes[None], axis=-1)
        # one named style: no other to tell it from, so no clip counts as in it
        self.style_gap = float(gaps[~np.eye(len(gaps), dtype=bool)].min()) if len(gaps) > 1 else 0.0
        self.max_code_norm = CODE_NORM_LIMIT * float(np.linalg.norm(self.codes, axis=1).max())
        self.min_frames = padded_length(1, int(extra.get("receptive_field", BUCKET)))
        self.window = int(extra.get("window", WINDOW))
        declared = self.entry.graphs["style3d"].outputs[0].shape[-1]
        if declared != self.style_dim:
            raise ValueError(f"style codes have {self.style_dim} dims, the graphs {declared}")

    def styles(self) -> list[dict[str, Any]]:
        return [
            {
                "name": name,
                "clips": self.clips[i],
                "velocity_factor": round(self.velocity[i], 4),
                "speed": None if self.speed is None else round(self.speed[i], 4),
            }
            for i, name in sorted(enumerate(self.style_names), key=lambda item: item[1])
        ]

    # --- networks --------------------------------------------------------------------------

    def _padded(self, x: np.ndarray) -> tuple[np.ndarray, int]:
        """``x (F, C)`` standardised -> ``(1, C, T)`` float32 at its bucket, and the offset."""
        padded, offset = pad_mirrored(x, padded_length(len(x), self.min_frames))
        return np.ascontiguousarray(padded.T[None], dtype=np.float32), offset

    @staticmethod
    def _windows(x: np.ndarray, length: int = WINDOW) -> tuple[np.ndarray, int, int]:
        """``x (F, C)`` standardised -> windows ``(N, C, length)`` float32 at
        :func:`window_starts` (hop half a window), the offset of frame 0 and the length they
        cover (a clip shorter than a window is mirrored at both ends to one)."""
        offset = 0
        if len(x) < length:
            x, offset = pad_mirrored(x, length)
        windows = np.stack([x[s : s + length] for s in window_starts(len(x), length)])
        windows = np.ascontiguousarray(windows.transpose(0, 2, 1), dtype=np.float32)
        return windows, offset, len(x)

    @staticmethod
    def _blend(windows: np.ndarray, frames: int) -> np.ndarray:
        """Decoded windows ``(N, C, length)`` (as :meth:`_windows` cut them) -> ``(frames, C)``,
        overlaps blended with Hann weights (every weight > 0, so every frame is covered)."""
        length = windows.shape[2]
        weight = np.hanning(length + 2)[1:-1, None]
        total = np.zeros((frames, 1))
        out = np.zeros((frames, windows.shape[1]))
        for window, start in zip(windows, window_starts(frames, length), strict=True):
            out[start : start + length] += weight * window.T
            total[start : start + length] += weight
        return (out / total).astype(np.float32)

    def _style_net(self, graph: str, kind: str, features: np.ndarray) -> np.ndarray:
        x, _ = self._padded(Fe.standardize(features, self.stats, kind))
        name = self.sessions[graph].get_inputs()[0].name
        return self.run(graph, {name: x})[0][0]

    # --- style codes -----------------------------------------------------------------------

    def code_of_motion(self, canon: Motion, timer: StageTimer | None = None) -> StyleCode:
        """The 3D style code and velocity factor of a canonical clip at 30 fps."""
        timer = timer or StageTimer(self.name)
        with timer.stage("style_features"):
            enc = Fe.encode(canon)
            velocity = Fe.encoded_velocity_factor(enc, canon.fps)
        with timer.stage("style_encode"):
            code = self._style_net("style3d", "style3d", enc.style3d)
        return self._bounded(StyleCode(code, velocity, "style"))

    def code_of_keypoints(self, kp: Keypoints2D, timer: StageTimer | None = None) -> StyleCode:
        """The 2D style code of a video's keypoints (resampled to 30 fps); no velocity
        factor (a video's joint speeds are in image units), so no time warp."""
        timer = timer or StageTimer(self.name)
        with timer.stage("style_features"):
            features = Fe.style2d_from_keypoints(kp)
        with timer.stage("style_encode"):
            code = self._style_net("style2d", "style2d", features)
        return self._bounded(StyleCode(code, None, "keypoints"))

    def _bounded(self, style: StyleCode) -> StyleCode:
        """``style`` with its code scaled down to ``max_code_norm`` (and a warning) when
        it lies beyond every style the decoder learned."""
        norm = float(np.linalg.norm(style.code))
        if norm <= self.max_code_norm:
            return style
        scaled = (style.code * np.float32(self.max_code_norm / norm)).astype(np.float32)
        what = {"style": "style clip", "keypoints": "video keypoints"}.get(style.source, "input")
        style.warnings.append(
            f"the style code of the {what} (norm {norm:.1f}) lies far outside the learned "
            f"styles (up to {self.max_code_norm:.1f}): scaled down to that norm"
        )
        return StyleCode(scaled, style.velocity, style.source, style.warnings, style.speed)

    def require_style(self, name: str) -> int:
        """The table row of style ``name``; 404 problem listing the known styles if none."""
        if name not in self.index:
            raise NotFound(
                f"no translator style named {name!r}",
                styles=sorted(self.style_names),
                model=self.name,
            )
        return self.index[name]

    def code_of_name(self, name: str) -> StyleCode:
        i = self.require_style(name)
        speed = None if self.speed is None else self.speed[i]
        return StyleCode(self.codes[i].copy(), self.velocity[i], "style_name", speed=speed)

    def code_of_mix(self, mix: dict[str, float]) -> StyleCode:
        """Weighted mean of named codes (and of their velocity factors; geometric mean of
        their speeds); weights >= 0 with a positive sum, normalised here; unknown names 404."""
        rows = [self.require_style(name) for name in mix]
        weights = np.array(list(mix.values()), dtype=np.float64)
        if not np.all(np.isfinite(weights)) or (weights < 0).any() or weights.sum() <= 0:
            raise InvalidStyle("'style_mix' weights must be >= 0 with a positive sum")
        weights /= weights.sum()
        code = (weights[:, None] * self.codes[rows].astype(np.float64)).sum(axis=0)
        velocity = float(np.dot(weights, [self.velocity[i] for i in rows]))
        speed = None
        if self.speed is not None:
            speed = float(np.exp(np.dot(weights, np.log([self.speed[i] for i in rows]))))
        return StyleCode(code.astype(np.float32), velocity, "style_mix", speed=speed)

    def nearest(self, code: np.ndarray, count: int = NEAREST) -> list[dict[str, Any]]:
        """The ``count`` named styles nearest to ``code`` (Euclidean), nearest first."""
        distances = np.linalg.norm(self.codes - np.asarray(code, dtype=np.float32), axis=1)
        order = np.argsort(distances, kind="stable")[:count]
        return [
            {"style": self.style_names[i], "distance": round(float(distances[i]), 4)} for i in order
        ]

    def own_speed(self, own: np.ndarray) -> float:
        """The speed of the named style a clip's own code ``own`` is in: that style's within
        ``SAME_STYLE_NEAR`` x the smallest gap between named codes, 1 (no style) beyond
        ``SAME_STYLE_FAR`` x it, geometrically between; 1 for bundles without speeds."""
        if self.speed is None or self.style_gap <= 0:
            return 1.0
        distances = np.linalg.norm(self.codes - np.asarray(own, dtype=np.float32), axis=1)
        i = int(np.argmin(distances))
        near, far = SAME_STYLE_NEAR * self.style_gap, SAME_STYLE_FAR * self.style_gap
        weight = min(max((far - float(distances[i])) / (far - near), 0.0), 1.0)
        return float(self.speed[i] ** weight)

    # --- transfer --------------------------------------------------------------------------

    def warp_factor(
        self,
        style_velocity: float | None,
        content_velocity: float,
        strength: float,
        style_speed: float | None = None,
    ) -> tuple[float, list[str]]:
        """``style_speed ** strength`` for a named style or mix, else ``(style / content) **
        strength`` (the paper's, for a style clip); clamped to [MIN_WARP, MAX_WARP]; and
        warnings."""
        if style_speed is not None:
            factor = style_speed**strength
        elif style_velocity is None:
            return 1.0, ["the style has no velocity factor (2D keypoints): no time warp"]
        elif not (style_velocity > 1e-6 and content_velocity > 1e-6):
            return 1.0, ["a clip hardly moves (velocity factor ~0): no time warp"]
        else:
            factor = (style_velocity / content_velocity) ** strength
        clamped = min(max(factor, MIN_WARP), MAX_WARP)
        if clamped != factor:
            return clamped, [
                f"time warp factor {factor:.3f} clamped to {clamped:g} "
                f"(allowed {MIN_WARP:g} to {MAX_WARP:g})"
            ]
        return factor, []

    def transfer(
        self,
        content: Motion,
        code: np.ndarray,
        strength: float = 1.0,
        time_warp: bool = True,
        foot_cleanup: bool = True,
        style_velocity: float | None = None,
        timer: StageTimer | None = None,
        style_speed: float | None = None,
    ) -> Transfer:
        """``content`` (canonical, 30 fps) in the style of ``code ``(S,)``; see the module
        docstring. The time warp is ``style_speed`` over the content's :meth:`own_speed`
        (named styles) or the ratio of velocity factors (style clips); neither means no time
        warp (with a warning if asked)."""
        timer = timer or StageTimer(self.name)
        frames = content.num_frames
        with timer.stage("features"):
            enc = Fe.encode(content)
            x_content = Fe.standardize(enc.content, self.stats, "content")
            x_style, _ = self._padded(Fe.standardize(enc.style3d, self.stats, "style3d"))
        with timer.stage("encode"):
            windows, offset, length = self._windows(x_content, self.window)
            latents = [
                self.run("content_encoder", {"content": windows[i : i + WINDOWS_PER_CALL]})[0]
                for i in range(0, len(windows), WINDOWS_PER_CALL)
            ]
            own = self.run("style3d", {"motion3d": x_style})[0][0]
        target = np.asarray(code, dtype=np.float32).reshape(own.shape)
        mixed = own + np.float32(strength) * (target - own)
        with timer.stage("decode"):
            decoded = [
                self.run("decoder", {"code": z, "style_code": np.repeat(mixed[None], len(z), 0)})[0]
                for z in latents
            ]
        with timer.stage("rotations"):
            out = self._blend(np.concatenate(decoded), length)
            output = Fe.unstandardize(out[offset : offset + frames], self.stats, "output")
            output = gaussian_filter1d(output, OUTPUT_SMOOTHING, axis=0, mode="nearest")
            motion = Fe.decode_motion(output, content, face=enc.facing)
        if foot_cleanup:
            with timer.stage("foot_cleanup"):
                contacts = CT.canonical_foot_contacts(content)
                motion = ik.pin_canonical_feet(motion, contacts, floor_of=content)
        warnings: list[str] = []
        factor = 1.0
        if time_warp:
            with timer.stage("time_warp"):
                content_velocity = Fe.encoded_velocity_factor(enc, content.fps)
                if style_speed is not None:
                    style_speed /= self.own_speed(own)
                factor, warnings = self.warp_factor(
                    style_velocity, content_velocity, strength, style_speed
                )
                if factor != 1.0:
                    motion = Fe.time_warp(motion, factor)
        return Transfer(motion, factor, warnings)


register_engine("translator", TranslatorEngine)

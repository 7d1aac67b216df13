"""The fast family: one small network per style name, distilled from the translator's
restyler (``training.fast_style``), onnxruntime only.

The family's core, :meth:`FastEngine.predict`, takes and returns canonical motion; the
service (through ``prepare`` and ``finish``) and the evaluations call the same one. A
canonical clip goes: the translator's features (``motion.features.encode``) -> the
restyler's input (head, hands, feet and travel about the clip's own mean posture,
standardised with the bundle's statistics, the translator's) -> mirrored at both ends (as
many frames as the networks see either side, then up to a multiple of ``BUCKET`` frames, so
onnxruntime sees few shapes and short clips still fill the receptive field) -> the style's
network, the whole clip in one call -> finished as the translator's restyler output is
(:func:`service.engines.restyling.restyled_motion`), at the style's ``strength`` (else the
bundle's; above 1: past the network's pose, away from the content's) -> played at the
style's speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from motion import features as Fe
from motion.anatomy import Warp
from motion.skeleton import Motion
from service.clips import Clip, Result, write_result
from service.engines import register_engine
from service.engines.base import Engine
from service.engines.restyling import (
    BUCKET,
    anatomical,
    clamp_warp,
    pad_mirrored,
    padded_length,
    restyled_motion,
    speed_limited,
    wrapped,
)
from service.errors import NotFound
from service.metrics import StageTimer
from service.requests import StylizeRequest


@dataclass
class FastJob:
    """The core's input: canonical ``content`` at 30 fps, the style's name, and the request's
    content clip (None when the caller gives canonical motion) for ``finish``."""

    content: Motion
    style: str
    foot_cleanup: bool = True
    time_warp: bool = True
    clip: Clip | None = None
    loop: bool = False  # ``content`` is a closed cycle, to wrap around


@dataclass
class Stylized:
    """The core's result: canonical motion at 30 fps and the time warp applied to it
    (``finish`` warps the original clip alike)."""

    motion: Motion
    warp: Warp
    warnings: list[str] = field(default_factory=list)


class FastEngine(Engine):
    family: ClassVar[str] = "fast"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": 2 * BUCKET}

    def load_assets(self) -> None:
        extra = self.entry.extra
        self.stats = Fe.FeatureStats.from_arrays(self.load_npz(extra["stats"]))
        self.style_info: dict[str, dict[str, Any]] = {
            name: info for name, info in extra.get("styles", {}).items()
            if info["graph"] in self.sessions
        }  # fmt: skip
        # other names of a style (Bandai's two datasets name three styles twice)
        self.aliases = {a: n for a, n in extra.get("aliases", {}).items() if n in self.style_info}
        self.strength = float(extra["strength"])  # model_export.fast's
        self.margin = int(extra["receptive_field"])  # frames the networks see either side
        # sigma in frames, chosen at export by model_export.output_smoothing
        self.output_smoothing = float(extra["output_smoothing"])

    def styles(self) -> list[dict[str, Any]]:
        return [
            {
                "name": name,
                "also_named": sorted(a for a, n in self.aliases.items() if n == name),
                "clips": info.get("clips"),
                "speed": info.get("speed"),
            }
            for name, info in sorted(self.style_info.items())
        ]

    def style_of(self, name: str) -> str | None:
        """The style ``name`` is, or is another name of; None if none."""
        name = self.aliases.get(name, name)
        return name if name in self.style_info else None

    def accepts(self, request: StylizeRequest) -> bool:
        return self.offers(request.style_name)

    def refusal(self, request: StylizeRequest) -> NotFound:
        return self._unknown(request.style_name)

    def _unknown(self, name: str) -> NotFound:
        return NotFound(
            f"no fast style named {name!r}",
            styles=sorted(self.style_info),
            model=self.name,
        )

    # --- the three steps ---------------------------------------------------------------------

    def prepare(self, request: StylizeRequest, timer: StageTimer) -> FastJob:
        content = request.content
        clip = content.load(self.settings, timer)
        return FastJob(clip.canonical, request.style_name, content.foot_cleanup,
                       content.time_warp, clip, loop=clip.loop is not None)  # fmt: skip

    def predict(self, job: FastJob, timer: StageTimer) -> Stylized:
        """The family's core: the style's network on the content, finished at the style's
        strength (:meth:`strength_of`), played at its speed with ``time_warp``."""
        style = self.style_of(job.style)
        if style is None:
            raise self._unknown(job.style)
        with timer.stage("features"):
            content, cycle = wrapped(job.content, job.loop, max(self.margin, BUCKET))
            enc = Fe.encode(content)
            x, offset = self.network_input(enc)
        with timer.stage("network"):
            output = self.run(self.style_info[style]["graph"], {"control": x})[0]
        channels = output[0, :, offset : offset + content.num_frames].T
        motion = restyled_motion(channels, content, enc, self.stats, timer, self.output_smoothing,
                                 self.strength_of(style), job.foot_cleanup)  # fmt: skip
        with timer.stage("anatomy"):
            motion = anatomical(motion, cycle, job.content)
        warnings: list[str] = []
        warp = Warp()
        if job.time_warp:
            with timer.stage("time_warp"):
                warp, warnings = speed_limited(self.warp_factor(style), motion)
                motion = warp.apply(motion)
        return Stylized(motion, warp, warnings)

    def finish(self, job: FastJob, out: Stylized, timer: StageTimer) -> Result:
        style = self.style_of(job.style)
        return write_result(job.clip, out.motion, self.settings, timer, suffix=style,
                            warp=out.warp, warnings=out.warnings)  # fmt: skip

    def network_input(self, enc: Fe.Encoded) -> tuple[np.ndarray, int]:
        """The networks' input ``(1, C, T)`` of an encoded canonical clip: the restyler's
        input mirrored at both ends (at least :attr:`margin` frames each), and where the
        clip starts in it."""
        control = Fe.restyler_input(enc.content, enc.style3d, self.stats)
        padded, offset = pad_mirrored(control, padded_length(len(control) + 2 * self.margin))
        return np.ascontiguousarray(padded.T[None], dtype=np.float32), offset

    def warp_factor(self, style: str) -> float:
        """How much faster than the content a style plays: its speed against the other
        styles on the same actions (the translator's), clamped to [MIN_WARP, MAX_WARP];
        1 for a bundle that gives none."""
        return clamp_warp(float(self.style_info[style].get("speed") or 1.0))

    def strength_of(self, style: str) -> float:
        """How far from the content's pose to the network's ``style`` is played: the style's
        own ``strength`` in the bundle, else the bundle's."""
        return float(self.style_info[style].get("strength", self.strength))


register_engine("fast", FastEngine)

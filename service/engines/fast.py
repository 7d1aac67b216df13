"""The fast family: one small network per style name, distilled from the translator's
restyler (``training.fast_style``), onnxruntime only.

A request's canonical clip goes: the translator's features (``motion.features.encode``)
-> the restyler's input (head, hands, feet and travel about the clip's own mean posture,
standardised with the bundle's statistics, the translator's) -> mirrored at both ends
(as many frames as the networks see either side, then up to a multiple of ``BUCKET``
frames, so onnxruntime sees few shapes and short clips still fill the receptive field)
-> the style's network, the whole clip in one call -> finished as the translator finishes
its own output, at the style's ``strength`` (else the bundle's)
(:func:`service.engines.translator.restyled_motion`: smoothed by the bundle's own
``output_smoothing``, taken that far from the
content's own pose (above 1: past the network's, away from the content's), on the
content's root trajectory, feet planted where the content's
are, on its floor, and clear of it where the content's are in the air) -> played at the
style's speed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from motion import features as Fe
from motion.skeleton import Motion
from service.clips import Clip, Result, Upload, load_clip, write_result
from service.engines import register_engine
from service.engines.base import Engine
from service.engines.translator import (
    BUCKET,
    MAX_WARP,
    MIN_WARP,
    pad_mirrored,
    padded_length,
    restyled_motion,
)
from service.errors import NotFound
from service.metrics import StageTimer
from service.requests import StylizeRequest


@dataclass
class FastJob:
    """A prepared stylization: the clip (None for a canonical motion given directly), its
    canonical motion and features, the padded network input ``(1, C, T)`` and where the
    clip starts in it."""

    clip: Clip | None
    canon: Motion
    style: str
    features: Fe.Encoded
    x: np.ndarray
    offset: int
    foot_cleanup: bool
    time_warp: bool = False


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
        # sigma in frames, chosen at export by training.output_smoothing
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
        return self.style_of(request.style_name) is not None

    def refusal(self, request: StylizeRequest) -> NotFound:
        return NotFound(
            f"no fast style named {request.style_name!r}",
            styles=sorted(self.style_info),
            model=self.name,
        )

    # --- the three steps ---------------------------------------------------------------------

    def prepare(self, request: StylizeRequest, timer: StageTimer) -> FastJob:
        clip = load_clip(
            request.content, self.settings, timer, mapping=request.mapping, answer=request.format
        )
        job = self._job(clip.canonical, request.style_name, request.foot_cleanup, timer, clip)
        job.time_warp = request.time_warp
        return job

    def _job(
        self,
        canon: Motion,
        style: str,
        foot_cleanup: bool,
        timer: StageTimer,
        clip: Clip | None = None,
    ) -> FastJob:
        if self.style_of(style) is None:
            raise self.refusal(StylizeRequest(Upload("content"), style))
        style = self.style_of(style)
        with timer.stage("features"):
            enc = Fe.encode(canon)
            control = Fe.restyler_input(enc.content, enc.style3d, self.stats)
            padded, offset = pad_mirrored(control, padded_length(len(control) + 2 * self.margin))
            x = np.ascontiguousarray(padded.T[None], dtype=np.float32)
        return FastJob(clip, canon, style, enc, x, offset, foot_cleanup)

    def predict(self, job: FastJob, timer: StageTimer) -> np.ndarray:
        """The style's network: ``(1, OUTPUT_CHANNELS, T)``."""
        with timer.stage("network"):
            return self.run(self.style_info[job.style]["graph"], {"control": job.x})[0]

    def finish(self, job: FastJob, output: np.ndarray, timer: StageTimer) -> Result:
        motion = self._motion(job, output, timer)
        factor = self.warp_factor(job.style) if job.time_warp else 1.0
        if factor != 1.0:
            with timer.stage("time_warp"):
                motion = Fe.time_warp(motion, factor)
        return write_result(job.clip, motion, self.settings, timer, suffix=job.style, warp=factor)

    def warp_factor(self, style: str) -> float:
        """How much faster than the content a style plays: its speed against the other
        styles on the same actions (the translator's), clamped to [MIN_WARP, MAX_WARP];
        1 for a bundle that gives none."""
        speed = float(self.style_info[style].get("speed") or 1.0)
        return min(max(speed, MIN_WARP), MAX_WARP)

    def strength_of(self, style: str) -> float:
        """How far from the content's pose to the network's ``style`` is played: the style's
        own ``strength`` in the bundle, else the bundle's."""
        return float(self.style_info[style].get("strength", self.strength))

    def _motion(self, job: FastJob, output: np.ndarray, timer: StageTimer) -> Motion:
        """The network's output -> a canonical motion, as the translator finishes its own
        at the style's strength (:meth:`strength_of`)."""
        frames = job.canon.num_frames
        channels = output[0, :, job.offset : job.offset + frames].T
        return restyled_motion(
            channels,
            job.canon,
            job.features,
            self.stats,
            timer,
            self.output_smoothing,
            self.strength_of(job.style),
            job.foot_cleanup,
        )

    def stylize(
        self,
        canon: Motion,
        style: str,
        timer: StageTimer | None = None,
        foot_cleanup: bool = True,
        time_warp: bool = True,
    ) -> Motion:
        """A canonical motion at 30 fps in ``style`` (the content's trajectory and rate,
        played at the style's speed with ``time_warp``): the three steps without an upload,
        for the evaluations."""
        timer = timer or StageTimer(self.name)
        job = self._job(canon, style, foot_cleanup, timer)
        motion = self._motion(job, self.predict(job, timer), timer)
        factor = self.warp_factor(job.style) if time_warp else 1.0
        return motion if factor == 1.0 else Fe.time_warp(motion, factor)


register_engine("fast", FastEngine)

"""The fast family (holden2017): one small transformation network per style name, and the
loss network's autoencoder as manifold projection, all onnxruntime.

A request's canonical clip goes: features (``motion.fast_features``, standardised with the
bundle's statistics) -> edge padding (``MARGIN`` frames each side, then up to a multiple
of ``BUCKET`` frames, so onnxruntime sees few shapes and short clips still fill the
receptive field) -> style network -> projection -> raw features -> global positions (the
content's root trajectory, so the path is kept exactly) -> joint rotations by
``motion.fit.fit_positions`` (bone lengths exact, twist from the content) -> feet pinned
where the content's feet are planted, on the content's floor, and lifted clear of it where
the content's are in the air (``motion.ik.pin_canonical_feet`` with ``floor_of``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from motion import canonical as C
from motion import fast_features as FF
from motion import features as Fe
from motion import fit, ik
from motion import kinematics as K
from motion.skeleton import Motion
from service.engines import register_engine
from service.engines.base import Engine
from service.engines.translator import MAX_WARP, MIN_WARP
from service.errors import NotFound
from service.metrics import StageTimer
from service.pipeline import Clip, Result, Upload, load_clip, write_result

BUCKET = 64  # frames: padded lengths are multiples of this
MARGIN = 64  # frames of edge padding each side (the networks see about +-60 frames)


def padded_length(frames: int) -> int:
    """Length the networks run at for a clip of ``frames`` frames."""
    return -(-(frames + 2 * MARGIN) // BUCKET) * BUCKET


@dataclass
class StylizeRequest:
    """``POST /v1/stylize``: a content clip and one named style."""

    content: Upload
    style_name: str
    foot_cleanup: bool = True
    time_warp: bool = True
    mapping: dict[str, str] | None = None
    format: str | None = None  # of the answer; None: the content's


@dataclass
class FastJob:
    """A prepared stylization: the clip (None for a canonical motion given directly), its
    canonical motion, features and the padded network input ``(1, T, C)``."""

    clip: Clip | None
    canon: Motion
    style: str
    features: FF.Encoded
    x: np.ndarray
    foot_cleanup: bool
    time_warp: bool = False


class FastEngine(Engine):
    family: ClassVar[str] = "fast"
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": 2 * BUCKET}

    def load_assets(self) -> None:
        extra = self.entry.extra
        self.stats = FF.FastStats(**{k: v for k, v in self.load_npz(extra["stats"]).items()
                                     if k in ("mean", "std")})  # fmt: skip
        self.style_info: dict[str, dict[str, Any]] = {
            name: info for name, info in extra.get("styles", {}).items()
            if info["graph"] in self.sessions
        }  # fmt: skip
        # other names of a style (Bandai's two datasets name three styles twice)
        self.aliases = {a: n for a, n in extra.get("aliases", {}).items() if n in self.style_info}

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
            features = FF.encode(canon)
            z = self.stats.normalize(features.features)
            frames = len(z)
            after = padded_length(frames) - frames - MARGIN
            x = np.pad(z, ((MARGIN, after), (0, 0)), mode="edge")[None].astype(np.float32)
        return FastJob(clip, canon, style, features, x, foot_cleanup)

    def predict(self, job: FastJob, timer: StageTimer) -> np.ndarray:
        """The style's network, then the autoencoder's projection: ``(1, T, C)``."""
        with timer.stage("network"):
            styled = self.run(self.style_info[job.style]["graph"], {"motion": job.x})[0]
            return self.run("projection", {"motion": styled})[0]

    def finish(self, job: FastJob, projected: np.ndarray, timer: StageTimer) -> Result:
        motion = self._motion(job, projected, timer)
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

    def _motion(self, job: FastJob, projected: np.ndarray, timer: StageTimer) -> Motion:
        """The network's features -> a canonical motion: the content's root trajectory,
        joint rotations fitted to the positions, feet pinned where the content's are, on its
        floor, and clear of it where the content's are in the air."""
        canon, enc = job.canon, job.features
        with timer.stage("positions"):
            frames = canon.num_frames
            out = self.stats.denormalize(projected[0, MARGIN : MARGIN + frames])
            out[:, FF.POSITION_CHANNELS :] = enc.features[:, FF.POSITION_CHANNELS :]
            gpos, _ = FF.decode(out, enc.start, enc.heading, fps=canon.fps)
            gpos[:, 0] = K.global_positions(canon.slice(0, 1))[0, 0]
        with timer.stage("ik"):
            motion = fit.fit_positions(gpos, C.SKELETON, reference=canon, fps=canon.fps)
        if job.foot_cleanup:
            with timer.stage("foot_cleanup"):
                contacts = enc.features[:, FF.CONTACTS] > 0.5
                motion = ik.pin_canonical_feet(motion, contacts, floor_of=canon)
        return motion

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

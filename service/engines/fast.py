"""The fast family (holden2017): one small transformation network per style name, and the
loss network's autoencoder as manifold projection, all onnxruntime.

A request's canonical clip goes: features (``motion.fast_features``, standardised with the
bundle's statistics) -> edge padding (``MARGIN`` frames each side, then up to a multiple
of ``BUCKET`` frames, so onnxruntime sees few shapes and short clips still fill the
receptive field) -> style network -> projection -> raw features -> global positions (the
content's root trajectory, so the path is kept exactly) -> joint rotations by
``motion.ik.fit_positions`` (bone lengths exact, twist from the content) -> feet pinned
where the content's feet are planted (``motion.ik.pin_canonical_feet``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from motion import canonical as C
from motion import fast_features as FF
from motion import ik
from motion import kinematics as K
from motion.skeleton import Motion
from service.engines import register_engine
from service.engines.base import Engine
from service.errors import NotFound
from service.metrics import StageTimer

BUCKET = 64  # frames: padded lengths are multiples of this
MARGIN = 64  # frames of edge padding each side (the networks see about +-60 frames)


def padded_length(frames: int) -> int:
    """Length the networks run at for a clip of ``frames`` frames."""
    return -(-(frames + 2 * MARGIN) // BUCKET) * BUCKET


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

    def styles(self) -> list[dict[str, Any]]:
        return [
            {"name": name, "clips": info.get("clips"), "contents": info.get("contents", [])}
            for name, info in sorted(self.style_info.items())
        ]

    def has_style(self, name: str) -> bool:
        return name in self.style_info

    def require_style(self, name: str) -> str:
        """The graph of style ``name``; 404 problem when this model has no such style."""
        if name not in self.style_info:
            raise NotFound(
                f"no fast style named {name!r}", styles=sorted(self.style_info), model=self.name
            )
        return self.style_info[name]["graph"]

    def transform(self, z: np.ndarray, style: str) -> np.ndarray:
        """Standardised features ``(T, C)`` -> styled and projected ``(T, C)`` (network only)."""
        graph = self.require_style(style)
        frames = len(z)
        total = padded_length(frames)
        before = MARGIN
        x = np.pad(z, ((before, total - frames - before), (0, 0)), mode="edge")[None]
        styled = self.run(graph, {"motion": x.astype(np.float32)})[0]
        projected = self.run("projection", {"motion": styled})[0]
        return projected[0, before : before + frames]

    def stylize(
        self, canon: Motion, style: str, timer: StageTimer, foot_cleanup: bool = True
    ) -> Motion:
        """A canonical motion at 30 fps in ``style`` (same frames, trajectory and rate)."""
        with timer.stage("features"):
            enc = FF.encode(canon)
            z = self.stats.normalize(enc.features)
        with timer.stage("network"):
            out = self.stats.denormalize(self.transform(z, style))
        with timer.stage("positions"):
            out[:, FF.POSITION_CHANNELS :] = enc.features[:, FF.POSITION_CHANNELS :]
            gpos, _ = FF.decode(out, enc.start, enc.heading, fps=canon.fps)
            gpos[:, 0] = K.global_positions(canon.slice(0, 1))[0, 0]
        with timer.stage("ik"):
            motion = ik.fit_positions(gpos, C.SKELETON, reference=canon, fps=canon.fps)
        if foot_cleanup:
            with timer.stage("foot_cleanup"):
                contacts = enc.features[:, FF.CONTACTS] > 0.5
                motion = ik.pin_canonical_feet(motion, contacts)
        return motion


register_engine("fast", FastEngine)

"""The data plane: every request of every family runs through :meth:`DataPlane.infer`.

A route reads its HTTP fields into a request of :mod:`service.requests` and hands it here;
the data plane looks up the engine of the family that takes it (one lookup, one readiness
rule: :meth:`ModelRegistry.resolve`, which also picks among several models of a family by
the style names asked for), runs ``engine.infer`` (prepare -> predict ->
finish) in the inference pool (:mod:`service.inference`: queue, slots, timeout), times its
stages and counts the frames it made; the route turns the result into an HTTP answer.

It also answers the questions about style names that span the families (which family
ships a name), for registering and deleting the studio's own styles
(:class:`~service.registered_styles.StyleStore`).
"""

from __future__ import annotations

from typing import Any

from service import metrics
from service.errors import Conflict, NotFound
from service.inference import InferenceRunner
from service.manifest import FAMILIES
from service.metrics import StageTimer
from service.registered_styles import StyleStore
from service.registry import ModelRegistry


class DataPlane:
    """The models (``registry``), the inference pool (``runner``) and the registered styles
    (``styles``) of one app."""

    def __init__(
        self, registry: ModelRegistry, runner: InferenceRunner, styles: StyleStore
    ) -> None:
        self.registry = registry
        self.runner = runner
        self.styles = styles

    async def infer(self, family: str, request: Any, *, endpoint: str = "") -> Any:
        """``request`` through the engine of ``family`` that takes it, in the inference pool;
        the result carries the model and the stage timings. Frames made are counted under
        ``endpoint`` (the route template) and the model."""
        engine, request = self.registry.resolve(family, request)
        timer = StageTimer(engine.name)
        result = await self.runner.run(engine.infer, request, timer)
        result.model = (engine.name, engine.version)
        result.timer = timer
        frames = getattr(result, "frames", None)
        if frames is not None:
            metrics.count_frames(endpoint, engine.name, frames)
        return result

    # --- style names across the families ------------------------------------------------------

    def shipped_family(self, name: str) -> str | None:
        """The family that ships a style (or another name of one) named ``name``, in any
        model, or None."""
        if name in self.styles:
            return None
        for family in FAMILIES:
            if any(e.style_of(name) for e in self.registry.by_family(family)):
                return family
        return None

    def check_new_style(self, name: str) -> None:
        """409 when ``name`` is shipped, registered already, or the store is full (before
        the work of coding the clips; the store checks again when it adds the style)."""
        family = self.shipped_family(name)
        if family is not None:
            raise Conflict(f"{name!r} is a shipped {family} style: choose another name", style=name)
        self.styles.check_room(name)

    def delete_style(self, name: str) -> None:
        """Delete the registered style ``name``: 409 for a shipped one, 404 for none (503
        while the models load: which names are shipped is known once they are)."""
        if self.styles.remove(name):
            return
        if not self.registry.ready:
            self.registry.require_ready()
        family = self.shipped_family(name)
        if family is not None:
            raise Conflict(
                f"{name!r} is a shipped {family} style and cannot be deleted", style=name
            )
        raise NotFound(
            f"no registered style named {name!r}", registered=[s.name for s in self.styles.all()]
        )

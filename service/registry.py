"""The model registry: every model of the manifest and its engine, for the data plane.

At start-up it reads the manifest, checks every file's sha256, builds one engine per model
(the family's registered engine, or :class:`~service.engines.GenericEngine`) and loads it,
all in a background thread: the process answers ``/healthz`` at once and ``/readyz`` turns
200 when every model is loaded and warmed. A missing manifest, a missing file, a sha256
mismatch or a graph that fails to load keeps the service not ready, and ``/readyz`` says why.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from typing import Any, Literal

from motion import compiled
from service import metrics
from service.config import Settings
from service.engines import ENGINE_FACTORIES, Engine, EngineFactory, GenericEngine
from service.errors import NotFound, NotReady
from service.manifest import FAMILIES, Manifest, ManifestError, load_manifest, verify_files
from service.registered_styles import StyleStore

logger = logging.getLogger(__name__)

State = Literal["idle", "loading", "ready", "failed"]
ModelStatus = Literal["pending", "loading", "ready", "failed"]


class ModelRegistry:
    """Every model of the manifest, its engine and its status. Cheap to build; :meth:`start`
    (or :meth:`load`, blocking) does the work."""

    def __init__(
        self,
        settings: Settings,
        factories: Mapping[str, EngineFactory] | None = None,
        styles: StyleStore | None = None,
    ):
        self.settings = settings
        self.models_dir = settings.models_dir
        self._factories = factories  # None: the global ENGINE_FACTORIES, read at load time
        self.registered = styles  # the registered styles, handed to every engine
        self.state: State = "idle"
        self.manifest: Manifest | None = None
        self.engines: dict[str, Engine] = {}
        self.errors: dict[str, str] = {}  # model name (or "manifest") -> why it failed
        self._loading: str | None = None
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._closing = False

    # --- lifecycle -------------------------------------------------------------------------

    def start(self) -> None:
        """Load in a background thread; :attr:`ready` turns true when it has succeeded."""
        self.state = "loading"
        metrics.READY.set(0)
        self._thread = threading.Thread(target=self.load, name="model-loader", daemon=True)
        self._thread.start()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until loading has finished (either way); False on timeout."""
        return self._done.wait(timeout)

    def load(self) -> None:
        """Read the manifest, verify, build and load every engine (blocking)."""
        self.state = "loading"
        try:
            self._load()
        except Exception as exc:  # a bug in an engine factory or here: not ready, say why
            logger.exception("model loading failed")
            self.errors.setdefault("registry", f"{type(exc).__name__}: {exc}")
        finally:
            self._loading = None
            failed = self.errors or not all(e.ready for e in self.engines.values())
            self.state = "failed" if failed else "ready"
            self._record_metrics()
            self._done.set()
            logger.info(
                "models %s: %d loaded, %d failed", self.state, self.n_ready, len(self.errors)
            )

    def _load(self) -> None:
        compiled.warm()  # the motion core's compiled loops, before the first request needs them
        try:
            manifest = load_manifest(self.models_dir)
        except ManifestError as exc:
            self.errors["manifest"] = str(exc)
            return
        self.manifest = manifest
        factories = ENGINE_FACTORIES if self._factories is None else self._factories

        engines: dict[str, Engine] = {}
        for entry in manifest.models:
            factory = factories.get(entry.family, GenericEngine)
            try:
                engines[entry.name] = factory(
                    entry, self.models_dir, self.settings, styles=self.registered
                )
            except Exception as exc:
                logger.exception("cannot build the engine of %s", entry.name)
                self.errors[entry.name] = f"{type(exc).__name__}: {exc}"
        self.engines = engines

        for name, engine in engines.items():
            if self._closing:
                self.errors[name] = "shut down before loading"
                continue
            self._loading = name
            problems = verify_files(engine.entry, self.models_dir)
            if problems:
                self.errors[name] = "; ".join(problems)
                logger.error("model %s not loaded: %s", name, self.errors[name])
                continue
            try:
                engine.load()
            except Exception as exc:
                logger.exception("model %s failed to load", name)
                self.errors[name] = f"{type(exc).__name__}: {exc}"
                engine.close()

    def _record_metrics(self) -> None:
        """``motion_model_info`` per model of the manifest, and ``motion_ready``."""
        entries = list(self.manifest.models) if self.manifest else []
        loaded = {name: engine.ready for name, engine in self.engines.items()}
        metrics.record_models(entries, loaded, self.ready)

    def close(self) -> None:
        """Stop loading (between models) and drop every session."""
        self._closing = True
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        for engine in list(self.engines.values()):
            engine.close()

    # --- status ----------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        return self.state == "ready"

    @property
    def n_ready(self) -> int:
        return sum(e.ready for e in self.engines.values())

    def model_status(self, name: str) -> ModelStatus:
        if name in self.errors:
            return "failed"
        engine = self.engines.get(name)
        if engine is not None and engine.ready:
            return "ready"
        if self._loading == name:
            return "loading"
        return "failed" if self._done.is_set() else "pending"

    def reasons(self) -> list[str]:
        """Why the service is not ready, one line per cause (empty when ready)."""
        if self.ready:
            return []
        if self.state in ("idle", "loading"):
            done, total = self.n_ready, len(self.manifest.models) if self.manifest else 0
            return [f"models are loading ({done} of {total} ready)" if total else "loading"]
        out = [f"{name}: {why}" for name, why in self.errors.items()]
        out += [
            f"{name}: not loaded"
            for name, engine in self.engines.items()
            if not engine.ready and name not in self.errors
        ]
        return out

    def readiness(self) -> dict[str, Any]:
        """State, per-model status and reasons, for ``/readyz`` and ``/v1/models``."""
        models = []
        for entry in self.manifest.models if self.manifest else []:
            item: dict[str, Any] = {
                "name": entry.name,
                "family": entry.family,
                "version": entry.version,
                "status": self.model_status(entry.name),
            }
            if entry.name in self.errors:
                item["error"] = self.errors[entry.name]
            models.append(item)
        return {"state": self.state, "models": models, "reasons": self.reasons()}

    def require_ready(self) -> None:
        """Raise :class:`NotReady` (503) unless every model is loaded and warmed."""
        if not self.ready:
            info = self.readiness()
            headers = {"Retry-After": "5"} if self.state in ("idle", "loading") else None
            raise NotReady("; ".join(info["reasons"]), headers=headers, **info)

    # --- access for routes -----------------------------------------------------------------

    def engine_for(self, family: str, request: Any = None) -> Engine:
        """The first ready engine of ``family`` that accepts ``request``. None ready: 503
        while the models load or when they failed (:meth:`require_ready`), 404 when the
        manifest has no such model. Ready ones that all refuse: their 404 (an unknown
        style names the known ones)."""
        engines = self.by_family(family)
        for engine in engines:
            if engine.accepts(request):
                return engine
        if engines:
            raise engines[0].refusal(request)
        self.require_ready()
        raise NotFound(f"no {family} model is installed", models=sorted(self.engines))

    def by_family(self, family: str) -> list[Engine]:
        """Ready engines of ``family``, in manifest order."""
        return [e for e in self.engines.values() if e.entry.family == family and e.ready]

    def styles(self) -> dict[str, list[dict[str, Any]]]:
        """``{family: [{"name", "model", "clips"?}, ...]}`` over the ready engines."""
        return {
            family: [
                {**style, "model": engine.name}
                for engine in self.by_family(family)
                for style in engine.styles()
            ]
            for family in FAMILIES
        }

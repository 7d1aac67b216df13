"""The model registry: every model of the manifests and its engine, for the data plane.

At start-up it reads the manifest of every model folder (``MOTION_MODELS_DIR``: one, or
several side by side), checks every file's sha256, builds one engine per model (the family's
registered engine, or :class:`~service.engines.GenericEngine`) and loads it, all in a
background thread: the process answers ``/healthz`` at once and ``/readyz`` turns 200 when
every model is loaded and warmed. A missing manifest, a missing file, a sha256 mismatch, a
graph that fails to load, or two folders that hold models of one name (or two models of one
family from one library) keep the service not ready, and ``/readyz`` says why.

Which engine serves a request: :meth:`ModelRegistry.resolve` (style names, ``library:style``:
:mod:`service.style_names`).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from motion import compiled
from service import metrics, style_names
from service.config import Settings
from service.engines import ENGINE_FACTORIES, Engine, EngineFactory, GenericEngine
from service.errors import InvalidRequest, NotFound, NotReady
from service.manifest import (
    FAMILIES,
    Manifest,
    ManifestError,
    ModelEntry,
    library_of,
    load_manifest,
    verify_files,
)
from service.registered_styles import StyleStore

logger = logging.getLogger(__name__)

State = Literal["idle", "loading", "ready", "failed"]
ModelStatus = Literal["pending", "loading", "ready", "failed"]


class ModelRegistry:
    """Every model of the manifests, its engine and its status. Cheap to build; :meth:`start`
    (or :meth:`load`, blocking) does the work."""

    def __init__(
        self,
        settings: Settings,
        factories: Mapping[str, EngineFactory] | None = None,
        styles: StyleStore | None = None,
    ):
        self.settings = settings
        self.models_dirs = settings.models_dir
        self._factories = factories  # None: the global ENGINE_FACTORIES, read at load time
        # the registered styles, handed to every engine
        self.registered = styles if styles is not None else StyleStore.from_settings(settings)
        self.state: State = "idle"
        self.manifests: dict[Path, Manifest] = {}  # model folder -> its manifest, in order
        self.engines: dict[str, Engine] = {}
        # model name (or "manifest", "manifest N" of the Nth folder, "models") -> why it failed
        self.errors: dict[str, str] = {}
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
        for k, folder in enumerate(self.models_dirs, 1):
            try:
                self.manifests[folder] = load_manifest(folder)
            except ManifestError as exc:
                key = "manifest" if len(self.models_dirs) == 1 else f"manifest {k}"
                self.errors[key] = str(exc)
        if self.errors:
            return
        if clash := self._clash():
            self.errors["models"] = clash
            return
        factories = ENGINE_FACTORIES if self._factories is None else self._factories

        engines: dict[str, Engine] = {}
        for folder, entry in self.folder_entries():
            factory = factories.get(entry.family, GenericEngine)
            try:
                engines[entry.name] = factory(entry, folder, self.settings, styles=self.registered)
            except Exception as exc:
                logger.exception("cannot build the engine of %s", entry.name)
                self.errors[entry.name] = f"{type(exc).__name__}: {exc}"
        self.engines = engines

        for name, engine in engines.items():
            if self._closing:
                self.errors[name] = "shut down before loading"
                continue
            self._loading = name
            problems = verify_files(engine.entry, engine.models_dir)
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

    def _clash(self) -> str | None:
        """Why the folders' models cannot be served together (a model name twice, or two
        models of one family from one library: ``library:style`` would not say which), or
        None."""
        names = Counter(entry.name for entry in self.entries)
        twice = sorted(name for name, count in names.items() if count > 1)
        if twice:
            return f"models of the same name in two model folders: {', '.join(twice)}"
        libraries = Counter((entry.family, library_of(entry)) for entry in self.entries)
        shared = sorted(f"{family} {lib}" for (family, lib), n in libraries.items() if n > 1)
        if shared:
            return f"two models of one family from one library: {', '.join(shared)}"
        return None

    def folder_entries(self) -> list[tuple[Path, ModelEntry]]:
        """Every model of every folder, with its folder, in the folders' order."""
        return [(folder, e) for folder, manifest in self.manifests.items() for e in manifest.models]

    @property
    def entries(self) -> list[ModelEntry]:
        """Every model of every folder's manifest, in the folders' order."""
        return [entry for _, entry in self.folder_entries()]

    def _record_metrics(self) -> None:
        """``motion_model_info`` per model of the manifest, and ``motion_ready``."""
        entries = self.entries
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
            done, total = self.n_ready, len(self.entries)
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
        for entry in self.entries:
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
        """The engine of ``family`` that serves ``request`` (:meth:`resolve`)."""
        return self.resolve(family, request)[0]

    def resolve(self, family: str, request: Any = None) -> tuple[Engine, Any]:
        """The ready engine of ``family`` that serves ``request``, and the request as it
        takes it (style names without their ``library:``). None ready: 503 while the models
        load or when they failed (:meth:`require_ready`), 404 when no folder has such a
        model. A request that names no style: the first engine that accepts it (the first
        folder's). Named styles: the model that offers them, ``library:style`` saying which
        where several do. A bare name that several models offer, a ``library:`` that no
        model of the family has, or a mix of two models' styles: a 400 naming the choices.
        A style no model offers: a 404 naming the known ones."""
        engines = self.by_family(family)
        if not engines:
            self.require_ready()
            raise NotFound(f"no {family} model is installed", models=sorted(self.engines))
        names = style_names.requested(request)
        if not names:
            for engine in engines:
                if engine.accepts(request):
                    return engine, request
            raise engines[0].refusal(request)
        wanted = [style_names.split(name) for name in names]
        for library, _ in wanted:
            if library is not None and not any(_answers_to(e, library) for e in engines):
                raise InvalidRequest(
                    f"no {family} model of a library named {library!r}: the {family} models' "
                    f"libraries are {', '.join(sorted(e.library for e in engines))}",
                    library=library,
                    libraries=sorted(e.library for e in engines),
                )
        spelled = {}
        for i, (library, style) in enumerate(wanted):
            spelling = self._spelling(family, library, style, engines)
            if spelling != style:
                spelled[style] = spelling
                wanted[i] = (library, spelling)
        offering = [
            [e for e in engines if (lib is None or _answers_to(e, lib)) and e.offers(style)]
            for lib, style in wanted
        ]
        if any(
            lib is None and len(offer) > 1 for (lib, _), offer in zip(wanted, offering, strict=True)
        ):
            raise self._ambiguous(family, wanted, offering)
        for (library, style), offer in zip(wanted, offering, strict=True):
            if not offer:
                if family == "translator" and library is None and style in self.registered:
                    # registered with a model not served (any more): 409, register it again
                    self.registered.lookup(style, engines[0].name, engines[0].version)
                if library is None and len(engines) > 1:
                    raise NotFound(
                        f"no {family} model offers a style named {style!r}",
                        styles=sorted(self._qualified_names(family)),
                    )
                refusing = next(e for e in engines if library is None or _answers_to(e, library))
                raise refusing.refusal(style_names.only(request, style))
        serving = [e for e in engines if all(e in offer for offer in offering)]
        if serving:
            return serving[0], style_names.bare(request, spelled)
        owners = {name: offer[0].library for name, offer in zip(names, offering, strict=True)}
        raise InvalidRequest(
            "the styles of a mix must come from one model (two models' codes do not share "
            "a space): " + ", ".join(f"{name!r} is {lib}'s" for name, lib in owners.items()),
            field="style_mix",
            libraries=owners,
        )

    def _spelling(self, family: str, library: str | None, style: str, engines: list[Engine]) -> str:
        """``style`` as the models of ``library`` (any, without one) spell it: as given where
        one offers it so or a style is registered so, else the one shipped name it spells
        in another case, else a registered one (their names are lower case), else as given
        (for the 404)."""
        candidates = [e for e in engines if library is None or _answers_to(e, library)]
        registered = family == "translator" and library is None
        if any(e.offers(style) for e in candidates) or (registered and style in self.registered):
            return style
        found = {e.spelling(style) for e in candidates} - {None}
        if len(found) == 1:
            return found.pop()
        return style.lower() if registered and style.lower() in self.registered else style

    def _ambiguous(
        self,
        family: str,
        wanted: list[tuple[str | None, str]],
        offering: list[list[Engine]],
    ) -> InvalidRequest:
        """The 400 for bare names several models offer, listing ``library:style`` for each."""
        choices = {
            style: [style_names.qualified(e.library, style) for e in offer]
            for (library, style), offer in zip(wanted, offering, strict=True)
            if library is None and len(offer) > 1
        }
        listed = "; ".join(f"{style!r}: {', '.join(names)}" for style, names in choices.items())
        return InvalidRequest(
            f"{len(next(iter(choices.values())))} {family} models offer "
            + ("a style" if len(choices) == 1 else "styles")
            + f" of this name: say which as library:style ({listed})",
            styles=sorted(choices),
            choices=choices,
        )

    def _qualified_names(self, family: str) -> list[str]:
        return [
            style_names.qualified(engine.library, style["name"])
            for engine in self.by_family(family)
            for style in engine.styles()
        ]

    def by_family(self, family: str) -> list[Engine]:
        """Ready engines of ``family``, in the folders' and their manifests' order."""
        return [e for e in self.engines.values() if e.entry.family == family and e.ready]

    def styles(self) -> dict[str, list[dict[str, Any]]]:
        """``{family: [{"name", "model", "library", "licence", "qualified_name", "clips"?},
        ...]}`` over the ready engines; the translator's registered styles after its shipped
        ones, each with the model that coded it (and its library and licence, when that
        model is served)."""
        listing: dict[str, list[dict[str, Any]]] = {}
        for family in FAMILIES:
            engines = self.by_family(family)
            listing[family] = [
                {**style, **_provenance(engine, style["name"])}
                for engine in engines
                for style in engine.styles()
            ]
            if family == "translator" and engines:
                for registered in self.registered.all():
                    engine = self.engines.get(registered.model)
                    known = _provenance(engine, registered.name) if engine else {}
                    listing[family].append(
                        {**registered.listing(), **known, "model": registered.model}
                    )
        return listing


def _answers_to(engine: Engine, library: str) -> bool:
    """Whether ``library:style`` names a style of ``engine``: its library or its model name."""
    return library in (engine.library, engine.name)


def _provenance(engine: Engine, style: str) -> dict[str, str]:
    """Where a style comes from, for ``GET /v1/styles``."""
    entry = engine.entry
    return {
        "model": entry.name,
        "library": engine.library,
        "licence": entry.licence,
        "qualified_name": style_names.qualified(engine.library, style),
    }

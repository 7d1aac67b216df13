"""The engine base class: one model bundle from the manifest, owning its onnxruntime sessions
and its requests.

A family engine subclasses :class:`Engine`, loads whatever else its bundle holds in
:meth:`Engine.load_assets` (statistics, style codes), may give real warm-up inputs in
:meth:`Engine.warm_inputs`, lists its styles in :meth:`Engine.styles`, and serves its
family's requests in three steps (KServe's preprocess, predict, postprocess), which
:meth:`Engine.infer` runs (the data plane calls it in the inference pool, timed):

- :meth:`Engine.prepare`: read and parse the uploads, onto the canonical skeleton, features;
- :meth:`Engine.predict`: run the networks, and nothing else (so a change of graphs is local);
- :meth:`Engine.finish`: post-process, back onto the request's skeleton, write.

:meth:`Engine.offers` says whether it offers a style of a name (the registry picks the
model a request's style names belong to), :meth:`Engine.accepts` whether it can take a
request, and :meth:`Engine.refusal` the 404 when no engine of the family can.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from service.config import Settings
from service.errors import NotFound
from service.manifest import GraphSpec, ModelEntry, library_of
from service.metrics import StageTimer
from service.registered_styles import StyleStore

if TYPE_CHECKING:
    import onnxruntime

logger = logging.getLogger(__name__)

# onnxruntime's type strings -> numpy dtypes, for warm-up inputs
ORT_DTYPES: dict[str, Any] = {
    "tensor(float)": np.float32,
    "tensor(float16)": np.float16,
    "tensor(double)": np.float64,
    "tensor(int64)": np.int64,
    "tensor(int32)": np.int32,
    "tensor(int8)": np.int8,
    "tensor(uint8)": np.uint8,
    "tensor(bool)": np.bool_,
}


def create_session(
    path: Path, intra_op_threads: int, spinning: bool = False
) -> onnxruntime.InferenceSession:
    """One CPU session as the serving notes ask: ``intra_op_threads`` threads, one inter-op
    thread, sequential execution, no memory-pattern planning (inputs change shape).

    Its threads sleep between runs unless ``spinning``: onnxruntime's default busy-waits
    after each run, which took a core from the numpy work that follows (the translator's
    foot clean-up ran 30 ms instead of 14 for a 240-frame clip). Only graphs run thousands
    of times back to back gain from it (:attr:`Engine.spinning_graphs`)."""
    import onnxruntime as ort  # imported here: ``import service`` stays light

    options = ort.SessionOptions()
    options.intra_op_num_threads = intra_op_threads
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.enable_mem_pattern = False
    options.log_severity_level = 3  # errors only
    options.add_session_config_entry("session.intra_op.allow_spinning", "1" if spinning else "0")
    return ort.InferenceSession(str(path), sess_options=options, providers=["CPUExecutionProvider"])


def check_io(graph: str, spec: GraphSpec, session: onnxruntime.InferenceSession) -> None:
    """Raise ``ValueError`` when the manifest's declared inputs/outputs disagree with the graph
    (names, ranks, fixed dims). Undeclared lists (empty) are not checked."""
    for kind, declared, actual in (
        ("inputs", spec.inputs, session.get_inputs()),
        ("outputs", spec.outputs, session.get_outputs()),
    ):
        if not declared:
            continue
        want = {t.name: t.shape for t in declared}
        have = {t.name: list(t.shape) for t in actual}
        if set(want) != set(have):
            raise ValueError(
                f"graph {graph!r}: manifest declares {kind} {sorted(want)}, "
                f"the ONNX file has {sorted(have)}"
            )
        for name, shape in want.items():
            got = have[name]
            fixed_differ = any(
                isinstance(a, int) and isinstance(b, int) and a != b
                for a, b in zip(shape, got, strict=False)
            )
            if len(shape) != len(got) or fixed_differ:
                raise ValueError(
                    f"graph {graph!r}: {kind[:-1]} {name!r} has shape {got} in the ONNX file, "
                    f"{shape} in the manifest"
                )


class Engine:
    """A model bundle: its manifest entry, its sessions (one per graph), its readiness.

    Lifecycle (KServe style): ``Engine(entry, models_dir, settings)`` is cheap; :meth:`load`
    (run once, in the loader thread, after the sha256 check) creates the sessions, loads
    assets and warms every graph, then sets :attr:`ready`. Any exception from ``load`` marks
    the model failed and keeps the service not ready.
    """

    family: ClassVar[str] = ""
    # Sizes for symbolic dims in warm-up runs; unknown names: 1 if they say batch, else 64.
    warm_dims: ClassVar[dict[str, int]] = {"batch": 1, "time": 64, "frames": 64}
    # graphs whose session threads busy-wait between runs (see create_session)
    spinning_graphs: ClassVar[frozenset[str]] = frozenset()

    def __init__(
        self,
        entry: ModelEntry,
        models_dir: Path,
        settings: Settings,
        styles: StyleStore | None = None,
    ) -> None:
        self.entry = entry
        self.models_dir = Path(models_dir)
        self.settings = settings
        # the service's registered styles (one store for the app); None: the settings' folder
        self.registered = styles if styles is not None else StyleStore.from_settings(settings)
        self.sessions: dict[str, onnxruntime.InferenceSession] = {}
        self.warmup_ms: dict[str, float] = {}
        self.warnings: list[str] = []  # what loading found that a user should know; it serves
        self.ready = False

    @property
    def name(self) -> str:
        return self.entry.name

    @property
    def version(self) -> str:
        return self.entry.version

    @property
    def library(self) -> str:
        """The library it learned from: ``library:style`` names its styles."""
        return library_of(self.entry)

    def path(self, relative: str) -> Path:
        """A file of this bundle (as listed in the manifest) on disk."""
        return self.models_dir / relative

    def load(self) -> None:
        """Create a session per graph, check it against the manifest, load assets, warm up."""
        for graph, spec in self.entry.graphs.items():
            session = create_session(
                self.path(spec.file),
                self.settings.intra_op_threads,
                spinning=graph in self.spinning_graphs,
            )
            check_io(graph, spec, session)
            self.sessions[graph] = session
        self.load_assets()
        for graph in self.sessions:
            self.warm(graph)
        self.ready = True

    def load_assets(self) -> None:
        """Hook: load statistics, style codes, ... (files must be listed in the manifest)."""

    def load_npz(self, relative: str) -> dict[str, np.ndarray]:
        """Arrays of a ``.npz`` of this bundle (never pickles)."""
        with np.load(self.path(relative), allow_pickle=False) as data:
            return {key: data[key] for key in data.files}

    def warm_inputs(self, graph: str) -> dict[str, np.ndarray]:
        """Inputs for the warm-up run of ``graph``: zeros, symbolic dims from
        :attr:`warm_dims`. Override when zeros are not valid input."""
        feeds = {}
        for arg in self.sessions[graph].get_inputs():
            shape = [dim if isinstance(dim, int) else self._warm_dim(dim) for dim in arg.shape]
            dtype = ORT_DTYPES.get(arg.type)
            if dtype is None:
                raise ValueError(f"graph {graph!r}: cannot warm input {arg.name!r} of {arg.type}")
            feeds[arg.name] = np.zeros(shape, dtype=dtype)
        return feeds

    def _warm_dim(self, name: str | None) -> int:
        if name in self.warm_dims:
            return self.warm_dims[name]
        return 1 if name is None or "batch" in name.lower() else 64

    def warm(self, graph: str) -> None:
        """One dummy run of ``graph``, timed into :attr:`warmup_ms`."""
        started = time.perf_counter()
        self.sessions[graph].run(None, self.warm_inputs(graph))
        self.warmup_ms[graph] = (time.perf_counter() - started) * 1000.0
        logger.info("warmed %s/%s in %.1f ms", self.name, graph, self.warmup_ms[graph])

    def run(self, graph: str, feeds: dict[str, np.ndarray]) -> list[np.ndarray]:
        """Run one graph (blocking: from :meth:`predict`, in the inference pool)."""
        return self.sessions[graph].run(None, feeds)

    def styles(self) -> list[dict[str, Any]]:
        """Styles this model ships: ``[{"name": ..., "clips": ...}, ...]`` (clips optional)."""
        return []

    def style_of(self, name: str) -> str | None:
        """The shipped style ``name`` is, or is another name of; None if none."""
        return name if any(style["name"] == name for style in self.styles()) else None

    def offers(self, name: str) -> bool:
        """Whether a request may name the style ``name`` (a bare name) of this model."""
        return self.style_of(name) is not None

    def spelling(self, name: str) -> str | None:
        """The name (or other name) of a shipped style that ``name`` spells in another case
        ("Angry" for "angry"), or None: none, or several that differ only in case."""
        folded = name.casefold()
        found = {
            spelled
            for style in self.styles()
            for spelled in (style["name"], *style.get("also_named", ()))
            if spelled.casefold() == folded
        }
        return found.pop() if len(found) == 1 else None

    # --- requests -------------------------------------------------------------------------

    def accepts(self, request: Any) -> bool:
        """Whether this engine can serve ``request`` (cheap: called on the event loop)."""
        return True

    def refusal(self, request: Any) -> Exception:
        """The error when no engine of the family accepts ``request``."""
        return NotFound(f"model {self.name!r} cannot serve this request")

    def infer(self, request: Any, timer: StageTimer) -> Any:
        """``request`` through :meth:`prepare`, :meth:`predict` and :meth:`finish`, stages
        timed into ``timer`` (blocking: the data plane runs it in the inference pool)."""
        job = self.prepare(request, timer)
        outputs = self.predict(job, timer)
        return self.finish(job, outputs, timer)

    def prepare(self, request: Any, timer: StageTimer) -> Any:
        raise NotImplementedError(f"{type(self).__name__} serves no requests")

    def predict(self, job: Any, timer: StageTimer) -> Any:
        raise NotImplementedError(f"{type(self).__name__} serves no requests")

    def finish(self, job: Any, outputs: Any, timer: StageTimer) -> Any:
        raise NotImplementedError(f"{type(self).__name__} serves no requests")

    def close(self) -> None:
        self.ready = False
        self.sessions.clear()


class GenericEngine(Engine):
    """For a family with no registered engine: loads and warms its graphs, serves nothing,
    so readiness still means "every graph in the manifest runs"."""

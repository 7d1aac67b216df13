"""Prometheus metrics: every metric of the service is declared here, once.

=========================================  =========  ==========================================
metric                                     type       labels
=========================================  =========  ==========================================
motion_http_requests_total                 counter    endpoint, method, status
motion_http_request_duration_seconds       histogram  endpoint
motion_inference_stage_duration_seconds    histogram  model, stage
motion_frames_processed_total              counter    endpoint, model
motion_errors_total                        counter    type (problem slug: ``too-large``...)
motion_key_requests_total                  counter    key (the API key's name), endpoint, status
motion_inferences_in_flight                gauge      (none): inferences holding a slot
motion_inference_queue_depth               gauge      (none): requests waiting for a slot
motion_model_info                          gauge      name, version, family, sha256 (1 = loaded)
motion_ready                               gauge      (none): 1 when every model is ready
=========================================  =========  ==========================================

``endpoint`` is the route's path template (``/v1/models``), never the raw path, so labels
stay few; requests that match no route are ``unmatched``. ``sha256`` is the first 12 hex
digits of the model bundle's digest (:func:`bundle_digest`).

Engines time their stages with ``with stage("decode", model=self.name): ...`` or, to also
report them in ``Server-Timing`` and ``timings_ms``, with a :class:`StageTimer`.

Several worker processes: when ``PROMETHEUS_MULTIPROC_DIR`` is set (``python -m service``
sets it for ``--workers`` > 1 and empties it at start), prometheus-client writes each
worker's values to files there and ``GET /metrics`` aggregates them all, whichever worker
answers. Otherwise the default registry of this process is exposed. The variable must be
set before this module is first imported (prometheus-client decides at import).
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from prometheus_client import (
    REGISTRY,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    multiprocess,
)
from prometheus_client.exposition import choose_encoder

if TYPE_CHECKING:
    from service.manifest import ModelEntry

MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"
UNMATCHED = "unmatched"
HTTP_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})

_LATENCY_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120)

HTTP_REQUESTS = Counter(
    "motion_http_requests",
    "HTTP requests answered, by route template, method and status",
    ["endpoint", "method", "status"],
)
HTTP_LATENCY = Histogram(
    "motion_http_request_duration_seconds",
    "Time from receiving a request to the end of its response, by route template",
    ["endpoint"],
    buckets=_LATENCY_BUCKETS,
)
STAGE_LATENCY = Histogram(
    "motion_inference_stage_duration_seconds",
    "Time spent in one stage of an inference (decode, encode, decode-net, postprocess...)",
    ["model", "stage"],
    buckets=_LATENCY_BUCKETS,
)
FRAMES = Counter(
    "motion_frames_processed",
    "Motion frames produced by the models, by route template and model",
    ["endpoint", "model"],
)
ERRORS = Counter(
    "motion_errors",
    "Problem responses sent, by problem type (the slug of the problem's type URI)",
    ["type"],
)
KEY_REQUESTS = Counter(
    "motion_key_requests",
    "Requests that came with a known API key, by the key's name, route template and status",
    ["key", "endpoint", "status"],
)
IN_FLIGHT = Gauge(
    "motion_inferences_in_flight",
    "Inferences holding a slot of the pool (running, or abandoned by a timeout and still running)",
    multiprocess_mode="livesum",
)
QUEUE_DEPTH = Gauge(
    "motion_inference_queue_depth",
    "Requests waiting for an inference slot (beyond max_queued or queue_wait_s: 503)",
    multiprocess_mode="livesum",
)
MODEL_INFO = Gauge(
    "motion_model_info",
    "One series per model of the manifest: 1 when loaded and warmed, else 0",
    ["name", "version", "family", "sha256"],
    multiprocess_mode="livemin",
)
READY = Gauge(
    "motion_ready",
    "1 when every model is loaded and warmed (in every live worker), else 0",
    multiprocess_mode="livemin",
)


# --- recording ------------------------------------------------------------------------------


def observe_request(endpoint: str, method: str, status: int, seconds: float) -> None:
    """Count one answered request and its latency (called by the request-context middleware);
    ``status`` 0 (no response was started: the client went away) is labelled ``none``."""
    label = str(status) if status else "none"
    method = method if method in HTTP_METHODS else "other"  # clients choose it: keep it bounded
    HTTP_REQUESTS.labels(endpoint=endpoint, method=method, status=label).inc()
    HTTP_LATENCY.labels(endpoint=endpoint).observe(seconds)


def count_error(slug: str) -> None:
    """Count one problem response of type ``slug`` (called where problems are built)."""
    ERRORS.labels(type=slug).inc()


def count_key_request(key: str, endpoint: str, status: int) -> None:
    """Count one request of the API key named ``key`` (its name, never the key)."""
    KEY_REQUESTS.labels(key=key, endpoint=endpoint, status=str(status) if status else "none").inc()


def count_frames(endpoint: str, model: str, frames: int) -> None:
    """Add ``frames`` motion frames produced by ``model`` for ``endpoint``."""
    FRAMES.labels(endpoint=endpoint, model=model).inc(frames)


@contextmanager
def stage(name: str, *, model: str, timings: dict[str, float] | None = None) -> Iterator[None]:
    """Time the block into ``motion_inference_stage_duration_seconds{model, stage=name}``.

    With ``timings`` (a dict), also add the milliseconds under ``name``. The time is recorded
    whether the block succeeds or raises.
    """
    started = time.perf_counter()
    try:
        yield
    finally:
        seconds = time.perf_counter() - started
        STAGE_LATENCY.labels(model=model, stage=name).observe(seconds)
        if timings is not None:
            timings[name] = timings.get(name, 0.0) + seconds * 1000.0


class StageTimer:
    """The stages of one inference of ``model``: each observed into the stage histogram and
    kept in :attr:`ms` (name -> milliseconds, in order) for ``timings_ms`` and the
    ``Server-Timing`` header::

        timer = StageTimer(self.name)
        with timer.stage("decode"):
            ...
        response.headers["Server-Timing"] = timer.server_timing()
    """

    def __init__(self, model: str) -> None:
        self.model = model
        self.ms: dict[str, float] = {}

    def stage(self, name: str):
        return stage(name, model=self.model, timings=self.ms)

    def server_timing(self) -> str:
        """``decode;dur=1.2, encode;dur=3.4`` (stage names made token-safe)."""
        return ", ".join(f"{_token(name)};dur={ms:.1f}" for name, ms in self.ms.items())


def _token(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in name) or "stage"


def bundle_digest(entry: ModelEntry) -> str:
    """First 12 hex digits of the sha256 over the bundle's ``path sha256`` lines, sorted: one
    identity for all the files of a model (its graphs, statistics, configuration)."""
    lines = sorted(f"{f.path} {f.sha256}\n" for f in entry.files)
    return hashlib.sha256("".join(lines).encode()).hexdigest()[:12]


def record_models(entries: list[ModelEntry], loaded: dict[str, bool], ready: bool) -> None:
    """Set ``motion_model_info`` for every model of the manifest and ``motion_ready``."""
    for entry in entries:
        MODEL_INFO.labels(
            name=entry.name,
            version=entry.version,
            family=entry.family,
            sha256=bundle_digest(entry),
        ).set(1 if loaded.get(entry.name) else 0)
    READY.set(1 if ready else 0)


# --- exposition -----------------------------------------------------------------------------


def multiprocess_dir() -> str | None:
    return os.environ.get(MULTIPROC_ENV) or None


def exposition(accept: str = "") -> tuple[bytes, str]:
    """Every metric (all workers' in multiprocess mode) and the content type: the Prometheus
    text format 0.0.4, or OpenMetrics when the ``Accept`` header asks for it."""
    if multiprocess_dir():
        registry = CollectorRegistry()
        multiprocess.MultiProcessCollector(registry)
    else:
        registry = REGISTRY
    encode, content_type = choose_encoder(accept)
    return encode(registry), content_type


def mark_worker_dead() -> None:
    """At worker shutdown in multiprocess mode: drop this process's live gauges."""
    if multiprocess_dir():
        multiprocess.mark_process_dead(os.getpid())

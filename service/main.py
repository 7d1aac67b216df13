"""The app factory. Nothing happens at import: ``create_app()`` builds an app, its lifespan
loads the models (in a background thread) and starts the inference pool.

uvicorn calls the factory itself: ``uvicorn service.main:create_app --factory``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager

from fastapi import FastAPI

from service import auth, fbx, metrics, problems
from service.config import Settings, available_cpus
from service.dataplane import DataPlane
from service.engines import EngineFactory, import_family_engines
from service.inference import InferenceRunner
from service.middleware import RequestContextMiddleware, UploadLimitMiddleware
from service.registered_styles import StyleStore
from service.registry import ModelRegistry
from service.routes import dance, debug, health, models, styles, stylize, transfer
from service.routes import metrics as metrics_routes
from service.routes.preview import install_preview

logger = logging.getLogger(__name__)

DESCRIPTION = """Re-styles character animation (BVH) and generates dance from music.

Errors are RFC 9457 `application/problem+json`; see `service/errors.py` for the problem types.
Models are for research and evaluation only (see `GET /v1/models`)."""


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    if settings.oversubscribed:
        logger.warning(
            "%d workers x %d intra-op threads exceed the %d available cores",
            settings.workers,
            settings.intra_op_threads,
            available_cpus(),
        )
    auth.log_startup(settings)
    app.state.runner.start()
    app.state.registry.start()
    if settings.fbx_workers and fbx.installed():  # warm Blender before readiness
        app.state.blender_warm = threading.Event()
        threading.Thread(
            target=_start_blender,
            args=(app.state.registry, settings.fbx_workers, app.state.blender_warm),
            name="blender-start",
            daemon=True,
        ).start()
    try:
        yield
    finally:
        app.state.runner.close()
        app.state.registry.close()
        auth.close(app)
        metrics.mark_worker_dead()


def _start_blender(registry: ModelRegistry, workers: int, warm: threading.Event) -> None:
    """The FBX pool's Blender processes, once the models have loaded (they do not take the
    CPU the loading needs); readiness waits for them (``warm``, set even if none starts: the
    log says why), so a replica is never in rotation while Blender boots beside requests."""
    try:
        registry.wait()
        fbx.start(workers)
    finally:
        warm.set()


def create_app(
    settings: Settings | None = None, engines: Mapping[str, EngineFactory] | None = None
) -> FastAPI:
    """Build the service. ``settings`` default to the environment (``MOTION_*``); ``engines``
    (family -> engine factory) default to the registered ones (``register_engine``)."""
    settings = settings or Settings()
    import_family_engines()

    app = FastAPI(
        title="motion-style",
        version="0.1.0",
        description=DESCRIPTION,
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.blender_warm = None  # an Event while the FBX pool starts (lifespan)
    registered = StyleStore.from_settings(settings)
    app.state.registry = ModelRegistry(settings, engines, registered)
    app.state.runner = InferenceRunner(
        settings.max_concurrent_inferences,
        settings.request_timeout_s,
        settings.queue_wait_s,
        settings.max_queued,
    )
    app.state.dataplane = DataPlane(app.state.registry, app.state.runner, registered)

    problems.install(app)
    # add_middleware puts each new one outside the previous: the request context is outermost,
    # and a request without a key is refused before the upload limit reads its body
    app.add_middleware(UploadLimitMiddleware, max_bytes=settings.max_upload_bytes)
    auth.install(app, settings)
    app.add_middleware(RequestContextMiddleware)

    for router in (health.router, models.router, styles.router, metrics_routes.router):
        app.include_router(router)
    app.include_router(stylize.router)
    app.include_router(dance.router)
    app.include_router(transfer.router)
    if settings.debug_routes:
        app.include_router(debug.router)
    install_preview(app)
    return app

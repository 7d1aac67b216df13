"""Fixtures for the API tests: the real app (``create_app``) with its lifespan running, over the
shipped ``models/`` or a temporary models folder with a tiny ONNX graph built here."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from typing import Any

import pytest

from service.config import Settings
from service.main import create_app
from tests.api.helpers import blender_warm
from tests.api.translator_helpers import video_zip
from tests.rigs import FIXTURE

with warnings.catch_warnings():
    # Starlette asks for httpx2 (not installed); its TestClient still works with httpx.
    warnings.filterwarnings("ignore", message=".*starlette.testclient.*")
    from fastapi.testclient import TestClient


@pytest.fixture
def make_client() -> Iterator[Callable[..., TestClient]]:
    """``make_client(settings=None, engines=None, setup=None, wait=True)``: a client over a fresh
    app whose lifespan runs until the test ends; with ``wait`` it returns once the models have
    loaded or failed. ``setup(app)`` may add routes before the first request."""
    with ExitStack() as stack:

        def make(
            settings: Settings | None = None,
            engines: dict | None = None,
            setup: Callable[[Any], None] | None = None,
            wait: bool = True,
            **client_kwargs: Any,
        ) -> TestClient:
            app = create_app(settings, engines)
            if setup is not None:
                setup(app)
            client = stack.enter_context(TestClient(app, **client_kwargs))
            if wait:
                assert app.state.registry.wait(60), "models did not finish loading"
                assert blender_warm(app), "Blender workers did not finish starting"
            return client

        yield make


@pytest.fixture
def client(make_client: Callable[..., TestClient]) -> TestClient:
    """The app as shipped: settings from the environment, the repository's ``models/``."""
    return make_client()


@pytest.fixture(scope="module")
def shared_client() -> Iterator[TestClient]:
    """The app as shipped, one per test module (its graphs load and warm once)."""
    app = create_app()
    with TestClient(app) as client:
        assert app.state.registry.wait(120) and blender_warm(app)
        yield client


@pytest.fixture(scope="module")
def walk() -> bytes:
    """The CMU walk fixture's BVH bytes, the content most API tests send."""
    return FIXTURE.read_bytes()


@pytest.fixture(scope="module")
def treadmill_zip() -> bytes:
    """OpenPose keypoints of a real walk video ("teenage hooligan"), zipped."""
    return video_zip(27)

"""Schemathesis against the app's own OpenAPI, in-process (ASGI, no network): every operation
gets generated requests, valid and invalid; no answer may be a 5xx, and every answer must
conform to the schema (status codes, content types, bodies, headers).

The shipped models are loaded first, so model routes answer as in production. The
"schema-valid data is accepted" check is left out for uploads: the schema can say "a
file", not "a BVH a humanoid can be mapped from", so random bytes rightly get a 400."""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import positive_data_acceptance
from schemathesis.python import asgi

from service.main import create_app

app = create_app()


async def without_lifespan(scope, receive, send):
    """The app with its lifespan run once by this module (schemathesis may start and stop
    lifespans around calls, which would drop the loaded models)."""
    if scope["type"] == "lifespan":
        while (await receive())["type"] != "lifespan.shutdown":
            await send({"type": "lifespan.startup.complete"})
        await send({"type": "lifespan.shutdown.complete"})
        return
    await app(scope, receive, send)


schema = schemathesis.openapi.from_asgi("/openapi.json", without_lifespan)


@pytest.fixture(scope="module", autouse=True)
def loaded_app():
    app.state.runner.start()
    app.state.registry.load()  # blocking: the shipped models, verified and warmed
    assert app.state.registry.ready, app.state.registry.errors
    yield
    asgi.shutdown_lifespans()
    app.state.runner.close()
    app.state.registry.close()


@schema.parametrize()
@settings(max_examples=25, deadline=None, suppress_health_check=list(HealthCheck))
def test_api_conforms_to_its_schema(case):
    uploads = case.method == "POST"
    case.call_and_validate(excluded_checks=[positive_data_acceptance] if uploads else None)

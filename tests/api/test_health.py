"""Liveness, readiness and the Open Inference Protocol aliases over the shipped models."""

from __future__ import annotations


def test_healthz_is_ok(client):
    response = client.get("/healthz")
    assert response.status_code == 200
    assert response.json() == {"status": "ok"}


def test_readyz_is_ready_once_the_shipped_models_are_loaded(client):
    response = client.get("/readyz")
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["status"] == "ready"
    assert all(m["status"] == "ready" for m in body["models"])


def test_v2_live_and_ready(client):
    assert client.get("/v2/health/live").json() == {"live": True}
    response = client.get("/v2/health/ready")
    assert response.status_code == 200
    assert response.json() == {"ready": True}

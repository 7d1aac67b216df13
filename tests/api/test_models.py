"""GET /v1/models: the manifest as shipped, with load status and the licence note."""

from __future__ import annotations

import json

from service.config import REPO_MODELS_DIR


def test_models_returns_the_shipped_manifest(client):
    manifest = json.loads((REPO_MODELS_DIR / "manifest.json").read_text())
    response = client.get("/v1/models")
    assert response.status_code == 200
    body = response.json()
    assert body["schema_version"] == manifest["schema_version"] == 1
    assert body["state"] == "ready"
    assert [m["name"] for m in body["models"]] == [m["name"] for m in manifest["models"]]
    for served, shipped in zip(body["models"], manifest["models"], strict=True):
        assert served["loaded"] is True
        assert served["status"] == "ready"
        assert served["files"] == shipped["files"]


def test_models_says_they_are_for_research_only(client):
    note = client.get("/v1/models").json()["licence_note"]
    assert "research" in note and "CC BY-NC" in note

"""Helpers shared by the API tests."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest

PROBLEM_MEMBERS = ("type", "title", "status", "detail", "instance", "request_id")


def assert_problem(response: Any, status: int, slug: str | None = None) -> dict[str, Any]:
    """Check an RFC 9457 response and return its body."""
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    body = response.json()
    for member in PROBLEM_MEMBERS:
        assert member in body, (member, body)
    assert body["status"] == status
    assert body["instance"] == response.request.url.path
    assert body["request_id"] == response.headers["x-request-id"]
    assert body["type"].startswith("https://motion-style.example/problems/")
    if slug is not None:
        assert body["type"].endswith("/" + slug)
    assert "Traceback" not in response.text
    return body


def write_tiny_model(
    models_dir: Path,
    name: str = "tiny",
    family: str = "fast",
    *,
    sha256: str | None = None,
    inputs: list[dict] | None = None,
) -> dict[str, Any]:
    """Write ``models_dir/<name>/net.onnx`` (``y = relu(x)``, ``x: [batch, time, 3]``) and a
    manifest listing it; ``sha256`` overrides the true hash. Returns the manifest."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Relu", ["x"], ["y"])],
        "tiny",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["batch", "time", 3])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["batch", "time", 3])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    path = models_dir / name / "net.onnx"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(model.SerializeToString())
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    spec = [{"name": "x", "dtype": "float32", "shape": ["batch", "time", 3]}]
    manifest = {
        "schema_version": 1,
        "models": [
            {
                "name": name,
                "family": family,
                "version": "0.0.1",
                "files": [{"path": f"{name}/net.onnx", "sha256": sha256 or digest}],
                "graphs": {
                    "net": {
                        "file": f"{name}/net.onnx",
                        "opset": 17,
                        "inputs": spec if inputs is None else inputs,
                        "outputs": [{"name": "y", "dtype": "float32", "shape": spec[0]["shape"]}],
                    }
                },
                "training_data": ["none (test graph)"],
                "licence": "test only",
                "trained_at": "2025-01-01",
                "metrics": {"parity_max_abs": 0.0},
                "extra": {},
            }
        ],
    }
    (models_dir / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return manifest


def blender_warm(app, timeout: float = 120) -> bool:
    """Whether the FBX pool's Blender workers (if the app starts any) are warm within
    ``timeout``: readiness waits for them."""
    return app.state.blender_warm is None or app.state.blender_warm.wait(timeout)

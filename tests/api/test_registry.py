"""Start-up: the manifest is read, every file's sha256 checked, every graph loaded into an
onnxruntime session and warmed; anything wrong keeps the service not ready, and says why."""

from __future__ import annotations

import hashlib
import json
import threading

import pytest

from service.config import Settings
from service.engines import ENGINE_FACTORIES, Engine, GenericEngine, register_engine
from service.errors import NotFound
from tests.api.helpers import assert_problem, blender_warm, write_tiny_model

NO_ENGINES: dict = {}  # every family gets a GenericEngine, whatever is registered later


class StyledEngine(Engine):
    family = "fast"

    def load_assets(self) -> None:
        self.style_names = self.entry.extra.get("styles", ["happy"])

    def styles(self):
        return [{"name": name, "clips": 3} for name in self.style_names]


def settings_for(models_dir) -> Settings:
    return Settings(models_dir=models_dir, intra_op_threads=1)


def test_a_good_model_is_loaded_warmed_and_listed(make_client, tmp_path):
    write_tiny_model(tmp_path)
    client = make_client(settings_for(tmp_path), NO_ENGINES)

    response = client.get("/readyz")
    assert response.status_code == 200, response.text
    assert response.json()["models"] == [
        {"name": "tiny", "family": "fast", "version": "0.0.1", "status": "ready"}
    ]
    engine = client.app.state.registry.engines["tiny"]
    assert type(engine) is GenericEngine
    assert set(engine.warmup_ms) == {"net"}
    session = engine.sessions["net"]
    assert session.get_providers() == ["CPUExecutionProvider"]
    assert session.get_session_options().intra_op_num_threads == 1
    assert session.get_session_options().inter_op_num_threads == 1
    spinning = "session.intra_op.allow_spinning"
    assert session.get_session_options().get_session_config_entry(spinning) == "0"

    models = client.get("/v1/models").json()["models"]
    assert models[0]["name"] == "tiny" and models[0]["loaded"] is True
    assert models[0]["graphs"]["net"]["inputs"][0]["shape"] == ["batch", "time", 3]
    assert client.get("/v2/health/ready").json() == {"ready": True}


def test_a_sha256_mismatch_keeps_the_service_not_ready(make_client, tmp_path):
    write_tiny_model(tmp_path, sha256="0" * 64)
    client = make_client(settings_for(tmp_path), NO_ENGINES)

    body = assert_problem(client.get("/readyz"), 503, "not-ready")
    assert "sha256 mismatch for tiny/net.onnx" in body["detail"]
    assert body["state"] == "failed"
    assert body["models"][0]["status"] == "failed"
    assert "tiny/net.onnx" in body["models"][0]["error"]

    ready = assert_problem(client.get("/v2/health/ready"), 503, "not-ready")
    assert ready["ready"] is False
    assert client.get("/healthz").status_code == 200
    assert client.get("/v2/health/live").status_code == 200
    listed = client.get("/v1/models").json()["models"][0]
    assert listed["status"] == "failed" and listed["loaded"] is False
    assert "sha256 mismatch" in listed["error"]
    assert client.app.state.registry.engines["tiny"].sessions == {}


def test_a_missing_file_keeps_the_service_not_ready(make_client, tmp_path):
    write_tiny_model(tmp_path)
    (tmp_path / "tiny" / "net.onnx").unlink()
    client = make_client(settings_for(tmp_path), NO_ENGINES)
    body = assert_problem(client.get("/readyz"), 503, "not-ready")
    assert "missing file tiny/net.onnx" in body["detail"]


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (None, "manifest.json"),
        ("{not json", "not valid JSON"),
        (json.dumps({"schema_version": 2, "models": []}), "schema_version"),
        (
            json.dumps(
                {
                    "schema_version": 1,
                    "models": [
                        {
                            "name": "evil",
                            "family": "fast",
                            "version": "1",
                            "files": [{"path": "../etc/passwd", "sha256": "0" * 64}],
                            "graphs": {},
                            "licence": "x",
                        }
                    ],
                }
            ),
            "relative to the models folder",
        ),
    ],
)
def test_a_bad_manifest_keeps_the_service_not_ready(make_client, tmp_path, content, says):
    if content is not None:
        (tmp_path / "manifest.json").write_text(content)
    client = make_client(settings_for(tmp_path), NO_ENGINES)
    body = assert_problem(client.get("/readyz"), 503, "not-ready")
    assert says in body["detail"]
    assert_problem(client.get("/v1/models"), 503, "not-ready")
    assert client.get("/healthz").status_code == 200


def test_a_graph_that_disagrees_with_the_manifest_fails(make_client, tmp_path):
    write_tiny_model(tmp_path, inputs=[{"name": "motion", "shape": ["batch", "time", 3]}])
    client = make_client(settings_for(tmp_path), NO_ENGINES)
    body = assert_problem(client.get("/readyz"), 503)
    assert "manifest declares inputs ['motion']" in body["detail"]


def test_an_unloadable_graph_fails(make_client, tmp_path):
    manifest = write_tiny_model(tmp_path)
    onnx_file = tmp_path / "tiny" / "net.onnx"
    onnx_file.write_bytes(b"not an onnx graph")
    manifest["models"][0]["files"][0]["sha256"] = hashlib.sha256(b"not an onnx graph").hexdigest()
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    client = make_client(settings_for(tmp_path), NO_ENGINES)
    body = assert_problem(client.get("/readyz"), 503)
    assert body["models"][0]["status"] == "failed"


def test_readiness_flips_when_loading_is_done(make_client, tmp_path):
    write_tiny_model(tmp_path)
    release = threading.Event()

    class SlowEngine(GenericEngine):
        def load_assets(self) -> None:
            assert release.wait(30)

    client = make_client(settings_for(tmp_path), {"fast": SlowEngine}, wait=False)
    response = client.get("/readyz")
    body = assert_problem(response, 503, "not-ready")
    assert body["state"] == "loading"
    assert response.headers["retry-after"]
    assert client.get("/healthz").status_code == 200

    release.set()
    # where Blender is installed its workers start after the models, before readiness
    assert client.app.state.registry.wait(30) and blender_warm(client.app)
    assert client.get("/readyz").status_code == 200


def test_an_engine_factory_serves_its_family(make_client, tmp_path):
    manifest = write_tiny_model(tmp_path)
    manifest["models"][0]["extra"] = {"styles": ["happy", "sad"]}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    client = make_client(settings_for(tmp_path), {"fast": StyledEngine})

    styles = client.get("/v1/styles").json()
    assert styles == {
        "translator": [],
        "fast": [
            {
                "name": name,
                "model": "tiny",
                "clips": 3,
                "library": "tiny",
                "licence": "test only",
                "qualified_name": f"tiny:{name}",
            }
            for name in ("happy", "sad")
        ],
        "dance": [],
    }
    registry = client.app.state.registry
    assert isinstance(registry.engines["tiny"], StyledEngine)
    assert [e.name for e in registry.by_family("fast")] == ["tiny"]
    assert registry.engine_for("fast") is registry.engines["tiny"]
    with pytest.raises(NotFound, match="no translator model"):
        registry.engine_for("translator")


def test_register_engine(make_client, tmp_path):
    with pytest.raises(ValueError, match="unknown model family"):
        register_engine("karaoke", StyledEngine)

    write_tiny_model(tmp_path, family="dance")
    previous = ENGINE_FACTORIES.get("dance")
    register_engine("dance", StyledEngine)
    try:
        client = make_client(settings_for(tmp_path))
        assert isinstance(client.app.state.registry.engines["tiny"], StyledEngine)
        assert client.get("/v1/styles").json()["dance"][0]["name"] == "happy"
    finally:
        if previous is None:
            del ENGINE_FACTORIES["dance"]
        else:
            ENGINE_FACTORIES["dance"] = previous


def test_only_the_graphs_an_engine_names_busy_wait_between_runs(make_client, tmp_path):
    """Spinning threads take a core from the numpy work after a run; the dance rollout's
    step graph, run once per frame, keeps them."""

    class SpinningEngine(StyledEngine):
        spinning_graphs = frozenset({"net"})

    write_tiny_model(tmp_path)
    spinning = "session.intra_op.allow_spinning"
    for engines, want in ((NO_ENGINES, "0"), ({"fast": SpinningEngine}, "1")):
        client = make_client(settings_for(tmp_path), engines)
        assert client.get("/readyz").status_code == 200
        session = client.app.state.registry.engines["tiny"].sessions["net"]
        assert session.get_session_options().get_session_config_entry(spinning) == want

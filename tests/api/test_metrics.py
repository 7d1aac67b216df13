"""``GET /metrics`` and what feeds it: requests by route template, latency, problems by type,
inference stages, frames, model info and readiness; JSON access logs; several workers."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time

import pytest
from fastapi import FastAPI, Request
from prometheus_client.parser import text_string_to_metric_families

from service import metrics
from service.config import Settings
from service.log import JsonFormatter, RequestIdFilter, log_config
from service.manifest import Manifest
from tests.api.helpers import assert_problem, write_tiny_model
from tests.server import REPO


def samples(client) -> dict[tuple[str, tuple], float]:
    """``{(sample name, sorted labels): value}`` from GET /metrics."""
    response = client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain; version=0.0.4")
    out = {}
    for family in text_string_to_metric_families(response.text):
        for sample in family.samples:
            out[(sample.name, tuple(sorted(sample.labels.items())))] = sample.value
    return out


def value(snapshot, sample: str, **labels) -> float:
    return snapshot.get((sample, tuple(sorted(labels.items()))), 0.0)


def test_requests_are_counted_by_route_template_method_and_status(client):
    before = samples(client)
    for _ in range(3):
        client.get("/healthz")
    client.get("/v1/nope/deeper")
    client.post("/v1/models")
    after = samples(client)

    def delta(**labels):
        name = "motion_http_requests_total"
        return value(after, name, **labels) - value(before, name, **labels)

    assert delta(endpoint="/healthz", method="GET", status="200") == 3
    assert delta(endpoint="unmatched", method="GET", status="404") == 1
    assert delta(endpoint="/v1/models", method="POST", status="405") == 1
    count = "motion_http_request_duration_seconds_count"
    assert value(after, count, endpoint="/healthz") - value(before, count, endpoint="/healthz") == 3


def test_client_chosen_methods_do_not_make_new_label_values(client):
    before = samples(client)
    client.request("FOOBAR", "/healthz")
    after = samples(client)
    name = "motion_http_requests_total"
    labels = {"endpoint": "/healthz", "method": "other", "status": "405"}
    assert value(after, name, **labels) - value(before, name, **labels) == 1
    assert not any("FOOBAR" in str(key) for key in after)


def test_problems_are_counted_by_type(client):
    before = samples(client)
    client.get("/missing")
    client.get("/missing/too")
    after = samples(client)
    name = "motion_errors_total"
    assert value(after, name, type="not-found") - value(before, name, type="not-found") == 2


def test_upload_over_the_limit_is_counted_under_its_route(make_client):
    client = make_client(Settings(max_upload_bytes=10))
    before = samples(client)
    assert_problem(client.post("/v1/models", content=b"x" * 100), 413, "too-large")
    after = samples(client)
    labels = {"endpoint": "/v1/models", "method": "POST", "status": "413"}
    name = "motion_http_requests_total"
    assert value(after, name, **labels) - value(before, name, **labels) == 1
    name = "motion_errors_total"
    assert value(after, name, type="too-large") - value(before, name, type="too-large") == 1


def add_stage_route(app: FastAPI) -> None:
    @app.get("/_test/stages")
    async def run_stages(request: Request):
        def work():
            timer = metrics.StageTimer("test-model")
            with timer.stage("decode"):
                time.sleep(0.01)
            with timer.stage("decode-net"):
                pass
            metrics.count_frames("/_test/stages", "test-model", 240)
            return timer

        timer = await request.app.state.runner.run(work)
        return {"server_timing": timer.server_timing(), "ms": timer.ms}


def test_stage_timer_feeds_the_histogram_and_server_timing(make_client):
    client = make_client(setup=add_stage_route)
    before = samples(client)
    body = client.get("/_test/stages").json()
    after = samples(client)
    assert list(body["ms"]) == ["decode", "decode-net"]
    assert body["ms"]["decode"] >= 10
    assert body["server_timing"].startswith("decode;dur=")
    assert ", decode-net;dur=" in body["server_timing"]
    name = "motion_inference_stage_duration_seconds_count"
    for stage in ("decode", "decode-net"):
        labels = {"model": "test-model", "stage": stage}
        assert value(after, name, **labels) - value(before, name, **labels) == 1
    name = "motion_frames_processed_total"
    labels = {"endpoint": "/_test/stages", "model": "test-model"}
    assert value(after, name, **labels) - value(before, name, **labels) == 240
    assert value(after, "motion_inferences_in_flight") == 0


def test_stage_is_recorded_when_the_block_raises():
    labels = {"model": "m", "stage": "boom"}
    before = metrics.STAGE_LATENCY.labels(**labels)._sum.get()
    timings: dict[str, float] = {}
    with pytest.raises(RuntimeError), metrics.stage("boom", model="m", timings=timings):
        time.sleep(0.002)
        raise RuntimeError
    assert metrics.STAGE_LATENCY.labels(**labels)._sum.get() > before
    assert timings["boom"] >= 2


def test_model_info_and_readiness(make_client, tmp_path):
    manifest = Manifest.model_validate(write_tiny_model(tmp_path, name="tiny-info"))
    client = make_client(Settings(models_dir=tmp_path), engines={})  # a GenericEngine
    snapshot = samples(client)
    digest = metrics.bundle_digest(manifest.models[0])
    labels = {"name": "tiny-info", "version": "0.0.1", "family": "fast", "sha256": digest}
    assert len(digest) == 12
    assert value(snapshot, "motion_model_info", **labels) == 1
    assert value(snapshot, "motion_ready") == 1


def test_model_that_fails_to_load_is_0_and_not_ready(make_client, tmp_path):
    write_tiny_model(tmp_path, name="tiny-bad", sha256="0" * 64)
    client = make_client(Settings(models_dir=tmp_path), engines={})
    snapshot = samples(client)
    series = [k for k in snapshot if k[0] == "motion_model_info" and ("name", "tiny-bad") in k[1]]
    assert series and all(snapshot[k] == 0 for k in series)
    assert value(snapshot, "motion_ready") == 0


def test_openmetrics_on_request(client):
    response = client.get("/metrics", headers={"Accept": "application/openmetrics-text"})
    assert response.headers["content-type"].startswith("application/openmetrics-text")
    assert response.text.rstrip().endswith("# EOF")


def test_every_metric_is_declared_once_in_service_metrics():
    """Metric constructors appear in service/metrics.py and nowhere else in the service."""
    offenders = []
    for path in (REPO / "service").rglob("*.py"):
        if path.name == "metrics.py" and path.parent.name == "service":
            continue
        text = path.read_text()
        if any(f"{kind}(" in text for kind in ("Counter", "Histogram", "Summary")) and (
            "prometheus_client" in text
        ):
            offenders.append(str(path))
    assert not offenders


# --- logs -------------------------------------------------------------------------------------


def test_json_access_log_line(client, caplog):
    caplog.handler.addFilter(RequestIdFilter())
    caplog.handler.setFormatter(JsonFormatter())
    with caplog.at_level(logging.INFO, logger="service.access"):
        client.get("/healthz", headers={"X-Request-Id": "json-1"})
    lines = [json.loads(line) for line in caplog.text.splitlines() if line.strip()]
    access = [line for line in lines if line["logger"] == "service.access"]
    assert access
    line = access[-1]
    assert line["request_id"] == "json-1"
    assert line["method"] == "GET" and line["path"] == "/healthz" and line["status"] == 200
    assert isinstance(line["duration_ms"], float)
    assert line["level"] == "INFO" and line["ts"].endswith("Z")


def test_json_log_of_an_error_carries_the_traceback():
    record = logging.LogRecord("service.x", logging.ERROR, __file__, 1, "boom %s", (1,), None)
    try:
        raise ValueError("inner")
    except ValueError:
        record.exc_info = sys.exc_info()
    line = json.loads(JsonFormatter().format(record))
    assert line["message"] == "boom 1"
    assert "ValueError: inner" in line["exc"]


def test_log_config_formats():
    assert log_config("info", "json")["handlers"]["default"]["formatter"] == "json"
    assert log_config("info")["handlers"]["default"]["formatter"] == "text"
    with pytest.raises(ValueError):
        log_config("info", "xml")


# --- several workers ----------------------------------------------------------------------------


def test_multiprocess_mode_aggregates_every_process(tmp_path):
    """Two processes count requests into one PROMETHEUS_MULTIPROC_DIR; the exposition of a
    third shows the sum (what GET /metrics answers under several uvicorn workers)."""
    env = {**os.environ, "PROMETHEUS_MULTIPROC_DIR": str(tmp_path)}
    record = (
        "from service import metrics; "
        "metrics.observe_request('/healthz', 'GET', 200, 0.01); "
        "metrics.READY.set(1)"
    )
    for _ in range(2):
        result = subprocess.run([sys.executable, "-c", record], env=env, cwd=REPO, timeout=60)
        assert result.returncode == 0
    show = "from service import metrics; print(metrics.exposition()[0].decode())"
    result = subprocess.run(
        [sys.executable, "-c", show], env=env, cwd=REPO, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert (
        'motion_http_requests_total{endpoint="/healthz",method="GET",status="200"} 2.0'
        in result.stdout
    )


def test_python_m_service_prepares_the_multiprocess_folder(monkeypatch, tmp_path):
    from service.__main__ import prepare_metrics_dir

    monkeypatch.setenv("PROMETHEUS_MULTIPROC_DIR", "")  # restored (absent) after the test
    monkeypatch.delenv("PROMETHEUS_MULTIPROC_DIR")
    assert prepare_metrics_dir(1) is None
    assert "PROMETHEUS_MULTIPROC_DIR" not in os.environ
    made = prepare_metrics_dir(2)  # several workers: a fresh folder, set for the workers
    assert made and os.environ["PROMETHEUS_MULTIPROC_DIR"] == made and os.path.isdir(made)
    os.rmdir(made)
    monkeypatch.delenv("PROMETHEUS_MULTIPROC_DIR")

    folder = tmp_path / "metrics"
    folder.mkdir()
    (folder / "counter_123.db").write_bytes(b"stale")
    (folder / "keep.txt").write_text("not ours")
    monkeypatch.setenv("PROMETHEUS_MULTIPROC_DIR", str(folder))
    assert prepare_metrics_dir(1) == str(folder)
    assert sorted(p.name for p in folder.iterdir()) == ["keep.txt"]

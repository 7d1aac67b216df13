"""Limits and shutdown of a real server (``python -m service``, uvicorn, real sockets): the
request timeout, the concurrency bound and the upload limit hold over the network, and a
request in flight when SIGTERM arrives still gets its answer. ``/_debug/sleep`` holds an
inference thread; it exists only with ``MOTION_DEBUG_ROUTES=1``."""

from __future__ import annotations

import concurrent.futures
import signal
import socket
import time

import httpx
import pytest

from service.config import Settings
from service.main import create_app
from tests.api.helpers import PROBLEM_MEMBERS
from tests.server import ServerProcess

ENV = {
    "MOTION_DEBUG_ROUTES": "1",
    "MOTION_REQUEST_TIMEOUT_S": "3",
    "MOTION_MAX_CONCURRENT_INFERENCES": "1",
    "MOTION_MAX_UPLOAD_BYTES": "1000",
}


def assert_problem(response: httpx.Response, status: int, slug: str) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    body = response.json()
    assert all(member in body for member in PROBLEM_MEMBERS)
    assert body["type"].endswith("/" + slug)
    return body


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    log = tmp_path_factory.mktemp("server") / "server.log"
    with ServerProcess(env=ENV, log_path=log) as running:
        yield running


def test_debug_routes_are_off_by_default():
    paths = {getattr(route, "path", "") for route in create_app().router.routes}
    assert not any(path.startswith("/_debug") for path in paths)
    with_debug = create_app(Settings(debug_routes=True))
    assert "/_debug/sleep" not in with_debug.openapi()["paths"]  # never documented


def test_timeout_is_504_and_health_answers_meanwhile(server):
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        slow = pool.submit(httpx.get, server.url + "/_debug/sleep?seconds=5", timeout=30)
        time.sleep(0.3)
        started = time.perf_counter()
        assert httpx.get(server.url + "/healthz", timeout=5).status_code == 200
        assert time.perf_counter() - started < 1.0
        body = assert_problem(slow.result(), 504, "timeout")
    assert body["limit"] == 3.0
    time.sleep(2.5)  # the abandoned sleep keeps its thread until it ends


def test_one_inference_at_a_time(server):
    started = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        calls = [
            pool.submit(httpx.get, server.url + "/_debug/sleep?seconds=1", timeout=30)
            for _ in range(2)
        ]
        results = [call.result() for call in calls]
    assert [r.status_code for r in results] == [200, 200]
    assert time.perf_counter() - started >= 1.9  # the second waited for the first


def test_upload_limit_over_a_real_socket(server):
    body = assert_problem(
        httpx.post(server.url + "/v1/stylize", content=b"x" * 5000, timeout=10), 413, "too-large"
    )
    assert body["limit"] == 1000

    def chunks():
        for _ in range(50):
            yield b"x" * 100

    # without Content-Length: counted while the form is read, stopped past the limit
    headers = {"Content-Type": "multipart/form-data; boundary=b"}
    chunked = httpx.post(server.url + "/v1/stylize", content=chunks(), headers=headers, timeout=10)
    assert "content-length" not in chunked.request.headers
    assert_problem(chunked, 413, "too-large")
    # the connection was closed, not left half-read; the server still answers
    assert httpx.get(server.url + "/healthz", timeout=5).status_code == 200


def test_sigterm_lets_the_request_in_flight_finish(tmp_path):
    with ServerProcess(env=ENV, log_path=tmp_path / "server.log") as running:
        with concurrent.futures.ThreadPoolExecutor(1) as pool:
            in_flight = pool.submit(httpx.get, running.url + "/_debug/sleep?seconds=2", timeout=30)
            time.sleep(0.5)  # the request is being served
            running.signal()  # SIGTERM
            time.sleep(0.5)
            with pytest.raises(OSError), socket.create_connection(("127.0.0.1", running.port), 2):
                pass  # no new connections once shutting down
            response = in_flight.result()
        assert response.status_code == 200, response.text
        assert response.json()["slept"] >= 1.9
        # uvicorn re-raises the signal once it has shut down: "terminated by SIGTERM" (143)
        assert running.wait(15) in (0, -signal.SIGTERM), running.log()
        assert "Finished server process" in running.log()

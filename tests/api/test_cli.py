"""``python -m service`` and the settings; the service never imports torch."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from service.config import Settings, available_cpus

REPO = Path(__file__).resolve().parents[2]


def run_python(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *args], cwd=REPO, capture_output=True, text=True, timeout=timeout
    )


def test_help_works():
    result = run_python("-m", "service", "--help")
    assert result.returncode == 0, result.stderr
    for option in ("--host", "--port", "--workers"):
        assert option in result.stdout


def test_invalid_options_are_refused():
    result = run_python("-m", "service", "--workers", "0")
    assert result.returncode != 0
    assert "invalid settings" in result.stderr


def test_the_service_never_imports_torch():
    code = (
        "import service.main, sys; service.main.create_app(); "
        "assert 'torch' not in sys.modules, 'torch imported'; "
        "assert 'training' not in sys.modules, 'training imported'"
    )
    result = run_python("-c", code)
    assert result.returncode == 0, result.stderr


def test_settings_come_from_motion_variables(monkeypatch, tmp_path):
    monkeypatch.setenv("MOTION_MAX_FRAMES", "123")
    monkeypatch.setenv("MOTION_MODELS_DIR", str(tmp_path))
    settings = Settings()
    assert settings.max_frames == 123
    assert settings.models_dir == (tmp_path,)


def test_threads_per_worker_never_exceed_the_cores():
    cores = available_cpus()
    for workers in range(1, cores + 1):
        settings = Settings(workers=workers)
        assert settings.workers * settings.intra_op_threads <= cores
        assert settings.max_concurrent_inferences == max(1, cores // workers)
        assert not settings.oversubscribed
    assert Settings(workers=cores + 1).intra_op_threads == 1


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.slow
def test_the_server_starts_serves_and_shuts_down_on_sigterm():
    port = free_port()
    env = {**os.environ, "MOTION_LOG_LEVEL": "info"}
    server = subprocess.Popen(
        [sys.executable, "-m", "service", "--port", str(port)],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        base = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 90  # the shipped models load and warm up first
        while True:
            try:
                response = httpx.get(f"{base}/readyz", headers={"X-Request-Id": "live-1"})
                if response.status_code == 200 or time.monotonic() > deadline:
                    break
            except httpx.TransportError:
                assert server.poll() is None, server.stdout.read()
                assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.2)
        assert response.status_code == 200, response.text
        assert response.headers["x-request-id"] == "live-1"
        assert httpx.get(f"{base}/v1/models").json()["schema_version"] == 1
    finally:
        server.send_signal(signal.SIGTERM)
        output, _ = server.communicate(timeout=20)
    # uvicorn shuts down gracefully, then re-raises the signal it caught
    assert server.returncode in (0, -signal.SIGTERM), output
    assert "Application shutdown complete" in output
    assert "[live-1] GET /readyz 200" in output

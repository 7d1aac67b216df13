"""A short loopback load test of a real server (part of ``make test``): 8 clients for 5 s on
the GET endpoints; no errors, resident memory does not grow, latency is reported. The full
one (16 clients x 60 s) is ``make load`` (``python -m bench.load``)."""

from __future__ import annotations

import os

from bench.load import DEFAULT_PATHS, run_load
from tests.server import ServerProcess

CLIENTS = int(os.environ.get("MOTION_LOAD_CLIENTS", "8"))
DURATION_S = float(os.environ.get("MOTION_LOAD_SECONDS", "5"))
MAX_RSS_GROWTH_MB = 25.0


def test_short_load_has_no_errors_and_no_memory_growth(tmp_path, capsys):
    paths = (*DEFAULT_PATHS, "/metrics", "/")
    env = {"MOTION_LOG_LEVEL": "warning"}
    with ServerProcess(env=env, log_path=tmp_path / "server.log") as server:
        run_load(server.url, clients=CLIENTS, duration_s=1.0, paths=paths)  # warm-up
        result = run_load(
            server.url, clients=CLIENTS, duration_s=DURATION_S, paths=paths, pid=server.pid
        )
        log = server.log()
    with capsys.disabled():
        print(f"\n[load] {result.summary()}")
    assert result.errors == 0, (result.error_samples, log)
    assert result.requests > 50 * DURATION_S, result.summary()
    assert result.rss_growth_mb is not None and result.rss_growth_mb < MAX_RSS_GROWTH_MB, (
        result.summary()
    )

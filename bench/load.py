"""Loopback load test: N clients hammer GET endpoints of a real server for T seconds.

    python -m bench.load                        # starts `python -m service` itself, 16 x 60 s
    python -m bench.load --clients 8 --duration 5 --json
    python -m bench.load --url http://127.0.0.1:8000 --paths /healthz /v1/styles

Each client is a thread with one keep-alive connection, cycling through the paths. Reports
requests, errors (anything but 2xx, or a failed connection), throughput, latency p50/p95/p99
and the server's resident memory before and after (when it started the server itself, or
``--pid`` names it). Exits 1 on any error. Only loopback addresses are accepted: this is a
test of our own server on this machine, bounded in time and in request count.
"""

from __future__ import annotations

import argparse
import http.client
import ipaddress
import json
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

DEFAULT_PATHS = ("/healthz", "/readyz", "/v1/styles", "/v1/models", "/v2/health/ready")
MAX_DURATION_S = 600.0
MAX_REQUESTS_PER_CLIENT = 2_000_000


@dataclass
class LoadResult:
    clients: int
    duration_s: float
    requests: int = 0
    errors: int = 0
    error_samples: list[str] = field(default_factory=list)
    by_status: dict[str, int] = field(default_factory=dict)
    throughput_rps: float = 0.0
    p50_ms: float = 0.0
    p95_ms: float = 0.0
    p99_ms: float = 0.0
    max_ms: float = 0.0
    rss_start_mb: float | None = None
    rss_end_mb: float | None = None
    rss_peak_mb: float | None = None

    @property
    def rss_growth_mb(self) -> float | None:
        if self.rss_start_mb is None or self.rss_end_mb is None:
            return None
        return self.rss_end_mb - self.rss_start_mb

    def summary(self) -> str:
        rss = ""
        if self.rss_start_mb is not None:
            rss = (
                f", RSS {self.rss_start_mb:.1f} -> {self.rss_end_mb:.1f} MB "
                f"(peak {self.rss_peak_mb:.1f})"
            )
        return (
            f"{self.clients} clients x {self.duration_s:.1f} s: {self.requests} requests, "
            f"{self.errors} errors, {self.throughput_rps:.0f} req/s, p50 {self.p50_ms:.1f} ms, "
            f"p95 {self.p95_ms:.1f} ms, p99 {self.p99_ms:.1f} ms, max {self.max_ms:.1f} ms{rss}"
        )

    def as_dict(self) -> dict:
        return {**asdict(self), "rss_growth_mb": self.rss_growth_mb}


def require_loopback(host: str) -> None:
    """Refuse any target but this machine's loopback addresses."""
    if host == "localhost":
        return
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        raise SystemExit(f"load tests only target loopback addresses, not {host!r}") from None
    if not address.is_loopback:
        raise SystemExit(f"load tests only target loopback addresses, not {host!r}")


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for pid {pid}")


def percentile(sorted_values: list[float], q: float) -> float:
    if not sorted_values:
        return 0.0
    index = min(len(sorted_values) - 1, max(0, round(q / 100.0 * (len(sorted_values) - 1))))
    return sorted_values[index]


def run_load(
    base_url: str,
    *,
    clients: int = 16,
    duration_s: float = 60.0,
    paths: tuple[str, ...] = DEFAULT_PATHS,
    pid: int | None = None,
    timeout_s: float = 30.0,
) -> LoadResult:
    """Run the load and return what was measured (see the module docstring)."""
    url = urlsplit(base_url)
    host, port = url.hostname or "127.0.0.1", url.port or 80
    require_loopback(host)
    duration_s = min(float(duration_s), MAX_DURATION_S)
    result = LoadResult(clients=clients, duration_s=duration_s)
    latencies: list[list[float]] = [[] for _ in range(clients)]
    statuses: list[dict[str, int]] = [{} for _ in range(clients)]
    errors: list[list[str]] = [[] for _ in range(clients)]
    start_barrier = threading.Barrier(clients + 1)
    stop_at = [0.0]

    def client(k: int) -> None:
        conn: http.client.HTTPConnection | None = None
        start_barrier.wait()
        i = k  # clients start at different paths
        for _ in range(MAX_REQUESTS_PER_CLIENT):
            if time.perf_counter() >= stop_at[0]:
                break
            path = paths[i % len(paths)]
            i += 1
            began = time.perf_counter()
            try:
                if conn is None:
                    conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
                conn.request("GET", path, headers={"X-Request-Id": f"load-{k}-{i}"})
                response = conn.getresponse()
                response.read()
                status = response.status
                if response.getheader("connection", "").lower() == "close":
                    conn.close()
                    conn = None
            except (OSError, http.client.HTTPException) as exc:
                status = 0
                errors[k].append(f"{path}: {type(exc).__name__}: {exc}")
                if conn is not None:
                    conn.close()
                conn = None
            latencies[k].append(time.perf_counter() - began)
            key = str(status) if status else "failed"
            statuses[k][key] = statuses[k].get(key, 0) + 1
            if status and not 200 <= status < 300:
                errors[k].append(f"{path}: HTTP {status}")
        if conn is not None:
            conn.close()

    threads = [threading.Thread(target=client, args=(k,), daemon=True) for k in range(clients)]
    for thread in threads:
        thread.start()
    if pid is not None:
        result.rss_start_mb = result.rss_peak_mb = rss_mb(pid)
    began = time.perf_counter()
    stop_at[0] = began + duration_s
    start_barrier.wait()
    while any(t.is_alive() for t in threads):
        for thread in threads:
            thread.join(timeout=0.5)
        if pid is not None:
            result.rss_peak_mb = max(result.rss_peak_mb or 0.0, rss_mb(pid))
        if time.perf_counter() > stop_at[0] + timeout_s + 5:
            break  # a client stuck past its socket timeout: report what we have
    elapsed = time.perf_counter() - began
    if pid is not None:
        result.rss_end_mb = rss_mb(pid)
        result.rss_peak_mb = max(result.rss_peak_mb or 0.0, result.rss_end_mb)

    all_latencies = sorted(x * 1000.0 for per_client in latencies for x in per_client)
    for per_client in statuses:
        for key, count in per_client.items():
            result.by_status[key] = result.by_status.get(key, 0) + count
    all_errors = [e for per_client in errors for e in per_client]
    result.requests = len(all_latencies)
    result.errors = len(all_errors)
    result.error_samples = all_errors[:10]
    result.throughput_rps = result.requests / elapsed if elapsed > 0 else 0.0
    result.p50_ms = percentile(all_latencies, 50)
    result.p95_ms = percentile(all_latencies, 95)
    result.p99_ms = percentile(all_latencies, 99)
    result.max_ms = all_latencies[-1] if all_latencies else 0.0
    return result


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _start_server(workers: int) -> tuple[subprocess.Popen, str]:
    """``python -m service`` on a free loopback port; returns once /readyz answers 200."""
    port = _free_port()
    repo = Path(__file__).resolve().parent.parent
    process = subprocess.Popen(
        [sys.executable, "-m", "service", "--host", "127.0.0.1", "--port", str(port)]
        + ["--workers", str(workers), "--log-level", "warning"],
        cwd=repo,
        env={**os.environ},
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise SystemExit(f"the server exited with {process.returncode}")
        try:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
            conn.request("GET", "/readyz")
            if conn.getresponse().status == 200:
                conn.close()
                return process, url
            conn.close()
        except OSError:
            pass
        time.sleep(0.2)
    process.terminate()
    raise SystemExit("the server did not get ready within 60 s")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--url", help="a running server (loopback only); default: start one")
    parser.add_argument("--pid", type=int, help="the running server's pid, to measure its RSS")
    parser.add_argument("--workers", type=int, default=1, help="workers of the started server")
    parser.add_argument("--clients", type=int, default=16)
    parser.add_argument("--duration", type=float, default=60.0, help="seconds (at most 600)")
    parser.add_argument("--paths", nargs="+", default=list(DEFAULT_PATHS))
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)

    process = None
    url, pid = args.url, args.pid
    if url is None:
        process, url = _start_server(args.workers)
        pid = process.pid if args.workers == 1 else None
    try:
        result = run_load(
            url,
            clients=args.clients,
            duration_s=args.duration,
            paths=tuple(args.paths),
            pid=pid,
        )
    finally:
        if process is not None:
            process.terminate()
            process.wait(30)
    print(json.dumps(result.as_dict(), indent=2) if args.json else result.summary())
    for sample in result.error_samples:
        print("error:", sample, file=sys.stderr)
    sys.exit(1 if result.errors else 0)


if __name__ == "__main__":
    main()

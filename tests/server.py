"""A real ``python -m service`` (uvicorn) in a subprocess on a free loopback port, for tests
that need real sockets: graceful shutdown, load, the Docker command, the browser."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class ServerProcess:
    """``with ServerProcess(env={...}) as server: httpx.get(server.url + "/healthz")``.

    ``command`` defaults to ``python -m service --host 127.0.0.1 --port <free>``; pass one to
    run something else (``{port}`` in it is replaced). Output goes to a log file under
    ``log_dir`` (default: a temporary folder), shown by :meth:`log` when something fails.
    """

    def __init__(
        self,
        command: Sequence[str] | None = None,
        *,
        env: dict[str, str] | None = None,
        port: int | None = None,
        log_path: Path | None = None,
        ready_path: str = "/readyz",
        start_timeout: float = 180.0,
    ) -> None:
        self.port = port or free_port()
        default = [sys.executable, "-m", "service", "--host", "127.0.0.1", "--port", "{port}"]
        self.command = [part.replace("{port}", str(self.port)) for part in (command or default)]
        self.env = {**os.environ, **(env or {})}
        self.env.setdefault("MOTION_LOG_LEVEL", "info")
        self.log_path = log_path or Path(os.environ.get("TMPDIR", "/tmp")) / (
            f"motion-server-{self.port}.log"
        )
        self.ready_path = ready_path
        self.start_timeout = start_timeout
        self.process: subprocess.Popen | None = None
        self._log = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def pid(self) -> int:
        assert self.process is not None
        return self.process.pid

    def start(self) -> ServerProcess:
        self._log = open(self.log_path, "wb")  # noqa: SIM115 - closed in stop()
        self.process = subprocess.Popen(
            self.command, cwd=REPO, env=self.env, stdout=self._log, stderr=subprocess.STDOUT
        )
        deadline = time.monotonic() + self.start_timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}:\n{self.log()}")
            try:
                if httpx.get(self.url + self.ready_path, timeout=2).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.stop()
        raise RuntimeError(f"server not ready after {self.start_timeout} s:\n{self.log()}")

    def wait_every_worker_ready(self, timeout: float = 120.0) -> str:
        """Polls ``/metrics`` until ``motion_ready`` is 1 (the least over live workers: the
        first 200 from ``/readyz`` comes from one worker, and another may load its models
        seconds later on a busy machine); returns that exposition."""
        deadline = time.monotonic() + timeout
        while True:
            exposition = httpx.get(self.url + "/metrics", timeout=5).text
            if re.search(r"^motion_ready 1\.0$", exposition, re.MULTILINE):
                return exposition
            found = re.findall(r"^motion_ready .*$", exposition, re.MULTILINE)
            assert time.monotonic() < deadline, f"{found} after {timeout} s:\n{self.log()}"
            time.sleep(0.5)

    def signal(self, sig: int = signal.SIGTERM) -> None:
        assert self.process is not None
        self.process.send_signal(sig)

    def wait(self, timeout: float) -> int:
        assert self.process is not None
        return self.process.wait(timeout)

    def stop(self, timeout: float = 15.0) -> int | None:
        """SIGTERM, then SIGKILL after ``timeout``; returns the exit code."""
        if self.process is None:
            return None
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)
        if self._log is not None:
            self._log.close()
            self._log = None
        return self.process.returncode

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-6000:]
        except OSError:
            return "(no log)"

    def rss_bytes(self) -> int:
        """Resident memory of the server process (Linux ``/proc``)."""
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
        raise RuntimeError("no VmRSS")

    def __enter__(self) -> ServerProcess:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

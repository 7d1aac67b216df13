"""docker-compose.yml as a user runs it, with the "monitoring" profile: two API replicas
behind nginx and Prometheus. A style registered through the stack is used by both replicas;
with one replica stopped, requests through nginx keep succeeding; Prometheus scrapes both.
Where the official images cannot be pulled, deploy/compose.debian.yml swaps in nginx and
Prometheus from Debian's packages (built by ``make image``)."""

from __future__ import annotations

import os
import subprocess
import time

import httpx
import pytest

from tests.image.containers import (
    BASE,
    COMPOSE_FILE,
    DEBIAN_OVERRIDE,
    OFFICIAL_BASE,
    REPO,
    compose_command,
    counter,
    docker,
    needs_image,
    unique,
    wait_ready,
)
from tests.rigs import FIXTURE
from tests.server import free_port

COMPOSE = compose_command()
pytestmark = [
    needs_image,
    pytest.mark.skipif(
        COMPOSE is None, reason="no docker compose (apt-get install docker-compose)"
    ),
]
STYLE = "stack-walk"
TRANSFER = {"endpoint": "/v1/transfer", "method": "POST", "status": "200"}


class Stack:
    def __init__(self) -> None:
        self.project = unique("motionstack").replace("-", "")
        self.port, self.prometheus_port = free_port(), free_port()
        files = ["-f", str(COMPOSE_FILE)]
        if BASE != OFFICIAL_BASE:
            files += ["-f", str(DEBIAN_OVERRIDE)]
        self.command = [*COMPOSE, "-p", self.project, *files, "--profile", "monitoring"]
        self.env = {
            **os.environ,
            "PYTHON_IMAGE": BASE,
            "API_REPLICAS": "2",
            "HTTP_PORT": str(self.port),
            "PROMETHEUS_PORT": str(self.prometheus_port),
        }
        self.url = f"http://127.0.0.1:{self.port}"

    def run(self, *args: str, timeout: float = 300) -> str:
        result = subprocess.run([*self.command, *args], capture_output=True, text=True,
                                env=self.env, cwd=REPO, timeout=timeout)  # fmt: skip
        assert result.returncode == 0, f"{' '.join(args)}:\n{result.stderr[-3000:]}"
        return result.stdout

    def replicas(self) -> list[str]:
        """The running API containers' ids."""
        labels = [f"label=com.docker.compose.{k}" for k in (f"project={self.project}",
                                                             "service=api")]  # fmt: skip
        return sorted(docker("ps", "-q", "--no-trunc", "--filter", labels[0], "--filter",
                             labels[1]).stdout.split())  # fmt: skip

    def replica_get(self, container: str, path: str, check: bool = True) -> str:
        """GET ``path`` from one replica itself (inside its container), not through nginx."""
        script = "import urllib.request; print(urllib.request.urlopen(" \
                 f"'http://127.0.0.1:8000{path}', timeout=10).read().decode())"  # fmt: skip
        return docker("exec", container, "python", "-c", script, check=check).stdout

    def replica_metrics(self, container: str) -> str:
        return self.replica_get(container, "/metrics")

    def wait_every_replica_ready(self, timeout: float = 240) -> None:
        """Healthy (the HEALTHCHECK: /healthz, alive) comes before ready (/readyz: models
        warmed); until then nginx passes a replica's 503 on to the other one."""
        deadline = time.monotonic() + timeout
        for container in self.replicas():
            while self.replica_get(container, "/readyz", check=False) == "":
                assert time.monotonic() < deadline, f"{container} not ready"
                time.sleep(1)


@pytest.fixture(scope="module")
def stack():
    stack = Stack()
    try:
        stack.run("up", "-d", "--no-build", timeout=600)
        # each replica ready before anything goes through nginx: a replica still warming
        # answers 503, three of which rest it in nginx for fail_timeout (10 s), and the
        # tests would then see one replica take every request
        stack.wait_every_replica_ready()
        wait_ready(stack.url, timeout=240)
        yield stack
    except BaseException:
        print(stack.run("logs", "--tail", "40", timeout=60))
        raise
    finally:
        subprocess.run([*stack.command, "down", "-v", "--remove-orphans", "-t", "5"],
                       env=stack.env, cwd=REPO, capture_output=True, timeout=300)  # fmt: skip


def transfer(url: str, style: str) -> httpx.Response:
    files = {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}
    return httpx.post(url + "/v1/transfer", files=files, data={"style_name": style}, timeout=120)


def test_two_replicas_answer_behind_nginx(stack):
    assert len(stack.replicas()) == 2
    assert httpx.get(stack.url + "/nginx-health", timeout=10).status_code == 200
    r = httpx.get(stack.url + "/metrics", timeout=10)
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"


def test_a_style_registered_through_the_stack_is_used_by_either_replica(stack):
    clips = [("clips", ("walk.bvh", FIXTURE.read_bytes(), "text/plain"))]
    r = httpx.post(stack.url + "/v1/styles", data={"name": STYLE}, files=clips, timeout=120)
    assert r.status_code == 201, r.text[:500]
    replicas = stack.replicas()
    before = [counter(stack.replica_metrics(c), "motion_http_requests", **TRANSFER)
              for c in replicas]  # fmt: skip
    results = [transfer(stack.url, STYLE) for _ in range(6)]
    assert [r.status_code for r in results] == [200] * 6, results[0].text[:500]
    assert len({r.text for r in results}) == 1, "the replicas restyle differently"
    after = [counter(stack.replica_metrics(c), "motion_http_requests", **TRANSFER)
             for c in replicas]  # fmt: skip
    served = [a - b for a, b in zip(after, before, strict=True)]
    assert sum(served) == 6 and min(served) >= 1, served


def test_prometheus_scrapes_both_replicas(stack):
    replicas = set(stack.replicas())
    addresses = {
        docker(
            "inspect", "-f", "{{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}", c
        ).stdout.strip()
        + ":8000"
        for c in replicas
    }
    prometheus = f"http://127.0.0.1:{stack.prometheus_port}"
    deadline = time.monotonic() + 120
    while True:
        try:
            query = httpx.get(
                prometheus + "/api/v1/query",
                timeout=10,
                params={"query": 'motion_http_requests_total{job="motion-style"}'},
            )
            scraped = {s["metric"]["instance"] for s in query.json()["data"]["result"]}
        except (httpx.HTTPError, ValueError, KeyError):
            scraped = set()
        if scraped == addresses or time.monotonic() > deadline:
            break
        time.sleep(2)
    assert scraped == addresses
    targets = httpx.get(prometheus + "/api/v1/targets", timeout=10).json()["data"]
    health = {t["labels"]["instance"]: t["health"] for t in targets["activeTargets"]}
    assert health == dict.fromkeys(addresses, "up")


def test_requests_keep_succeeding_with_one_replica_stopped(stack):
    stopped, running = stack.replicas()
    docker("stop", "-t", "30", stopped)
    try:
        results = [transfer(stack.url, "proud") for _ in range(6)]
        assert [r.status_code for r in results] == [200] * 6, results[0].text[:500]
        assert "".join(stack.replicas()) == running
    finally:
        docker("start", stopped)

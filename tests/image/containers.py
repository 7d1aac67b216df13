"""The real image in Docker, for the image tests: whether they can run here, containers and
compose stacks that are always removed, and the service's own clips, songs and metrics.

They run under ``make image-test``, which builds the images (``make image``) and sets
``MOTION_IMAGE_BASE`` to the base they were built on; in a plain ``make test`` they skip.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest
import yaml
from prometheus_client.parser import text_string_to_metric_families

REPO = Path(__file__).resolve().parent.parent.parent
COMPOSE_FILE = REPO / "docker-compose.yml"
DEBIAN_OVERRIDE = REPO / "deploy" / "compose.debian.yml"
OFFICIAL_BASE = "python:3.11-slim-bookworm"
BASE = os.environ.get("MOTION_IMAGE_BASE", "")
IMAGE = yaml.safe_load(COMPOSE_FILE.read_text())["services"]["api"]["image"]
FBX_IMAGE = "motion-style:fbx"  # the image with the fbx extra (make image-fbx)
STYLES_DIR = "/var/lib/motion-style/styles"
UID = "10001"


def docker(*args: str, timeout: float = 120, check: bool = True) -> subprocess.CompletedProcess:
    result = subprocess.run(
        ["docker", *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    if check and result.returncode != 0:
        raise AssertionError(f"docker {' '.join(args)}: {result.stderr[-2000:]}")
    return result


def image_bytes(image: str) -> int:
    """``image``'s size as docker reports it."""
    return int(docker("image", "inspect", "-f", "{{.Size}}", image).stdout.strip())


def shell_output(image: str, script: str) -> str:
    """What ``script`` prints in a throwaway container of ``image`` (its entrypoint aside)."""
    return docker("run", "--rm", "--entrypoint", "sh", image, "-c", script).stdout.strip()


def compose_command() -> list[str] | None:
    """``docker compose`` (v2) or Debian's ``docker-compose`` (1.29), whichever is here."""
    if (
        shutil.which("docker")
        and subprocess.run(["docker", "compose", "version"], capture_output=True).returncode == 0
    ):
        return ["docker", "compose"]
    return [exe] if (exe := shutil.which("docker-compose")) else None


def why_not_here() -> str | None:
    if shutil.which("docker") is None:
        return "docker is not installed (make image-test installs docker.io)"
    try:
        info = subprocess.run(["docker", "info"], capture_output=True, timeout=30)
    except subprocess.TimeoutExpired:
        info = None
    if info is None or info.returncode != 0:
        return "no Docker engine answers (make image-test starts dockerd)"
    if not BASE:
        return "the image tests run under make image-test (it builds the images first)"
    if docker("image", "inspect", IMAGE, check=False).returncode != 0:
        return f"the image {IMAGE} is not built (make image)"
    return None


REASON = why_not_here()
needs_image = pytest.mark.skipif(REASON is not None, reason=REASON or "")


def unique(prefix: str) -> str:
    return f"{prefix}-{uuid.uuid4().hex[:8]}"


def wait_ready(url: str, timeout: float = 180.0, path: str = "/readyz") -> None:
    deadline = time.monotonic() + timeout
    last = ""
    while time.monotonic() < deadline:
        try:
            r = httpx.get(url + path, timeout=5)
            if r.status_code == 200:
                return
            last = f"{r.status_code} {r.text[:200]}"
        except httpx.HTTPError as exc:
            last = repr(exc)
        time.sleep(1)
    raise AssertionError(f"{url}{path} not ready after {timeout:.0f} s: {last}")


class Container:
    """``docker run`` of the image as a deployment runs it: read-only root, /tmp a tmpfs,
    registered styles on the named volume ``volume``, port 8000 on a free loopback port."""

    def __init__(self, volume: str, env: dict[str, str] | None = None, image: str = IMAGE) -> None:
        self.name = unique("motion-style-test")
        args = ["run", "-d", "--name", self.name, "--read-only", "--tmpfs", "/tmp"]
        args += ["-v", f"{volume}:{STYLES_DIR}", "-p", "127.0.0.1::8000"]
        for key, value in (env or {}).items():
            args += ["-e", f"{key}={value}"]
        docker(*args, image)
        host_port = docker("port", self.name, "8000/tcp").stdout.split()[0]
        self.url = "http://" + host_port.replace("0.0.0.0", "127.0.0.1")

    def inspect(self) -> dict:
        return json.loads(docker("inspect", self.name).stdout)[0]

    def logs(self) -> str:
        result = docker("logs", self.name, check=False)
        return (result.stdout + result.stderr)[-4000:]

    def exec(self, *command: str) -> subprocess.CompletedProcess:
        return docker("exec", self.name, *command, check=False)

    def wait_health(self, status: str, timeout: float = 120.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.inspect()["State"]["Health"]["Status"] == status:
                return
            time.sleep(1)
        raise AssertionError(f"not {status} after {timeout:.0f} s:\n{self.logs()}")

    def remove(self) -> None:
        docker("rm", "-f", self.name, check=False)


@contextmanager
def serving(volume: str, image: str = IMAGE) -> Iterator[Container]:
    """A ready container of ``image`` on ``volume``, its log printed if a test fails, always
    removed."""
    box = Container(volume, env={"MOTION_INTRA_OP_THREADS": "2"}, image=image)
    try:
        wait_ready(box.url)
        yield box
    except BaseException:
        print(box.logs())
        raise
    finally:
        box.remove()


def counter(exposition: str, name: str, **labels: str) -> float:
    """The value of counter ``name`` (its ``_total`` sample) with ``labels``, 0 if absent."""
    for family in text_string_to_metric_families(exposition):
        for sample in family.samples:
            if sample.name == name + "_total" and labels.items() <= sample.labels.items():
                return sample.value
    return 0.0


def gauge(exposition: str, name: str) -> float:
    for family in text_string_to_metric_families(exposition):
        for sample in family.samples:
            if sample.name == name:
                return sample.value
    return 0.0

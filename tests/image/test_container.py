"""The service image as a user deploys it, driven over HTTP: a read-only container running as
uid 10001 whose healthcheck turns healthy; every endpoint with the shipped models (BVH, GLB,
an MP3 dance, a registered style); registered styles kept on the volume when the container
is replaced; /metrics counting requests; SIGTERM during a long request finishing it and the
container exiting 0. The image itself: under 750 MB, without pip, setuptools or test suites.
"""

from __future__ import annotations

import math
import threading
import time

import httpx
import numpy as np
import pygltflib
import pytest

from motion import audio_decode, bvh
from tests.gltf_files import character_glb
from tests.image.containers import (
    IMAGE,
    STYLES_DIR,
    UID,
    counter,
    docker,
    gauge,
    image_bytes,
    needs_image,
    serving,
    shell_output,
    unique,
)
from tests.rigs import FIXTURE
from training.songs import encoded, song

pytestmark = needs_image

MAX_IMAGE_BYTES = 750e6  # docker's "MB"
GLB = "model/gltf-binary"
STYLE = "studio-walk"


@pytest.fixture(scope="module")
def volume():
    name = unique("motion-style-test-styles")
    docker("volume", "create", name)
    yield name
    docker("volume", "rm", "-f", name, check=False)


@pytest.fixture(scope="module")
def container(volume):
    with serving(volume) as box:
        yield box


@pytest.fixture(scope="module")
def replacement(volume):
    """A second container on the same volume, started when a test first asks for it (after
    the first is removed); the shutdown test ends it."""
    with serving(volume) as box:
        yield box


@pytest.fixture(scope="module")
def client(container):
    with httpx.Client(base_url=container.url, timeout=120) as c:
        yield c


@pytest.fixture(scope="module")
def styles(client) -> dict:
    r = client.get("/v1/styles")
    assert r.status_code == 200, r.text
    return r.json()


def bvh_file(data: bytes | None = None) -> tuple[str, bytes, str]:
    return ("walk.bvh", data or FIXTURE.read_bytes(), "text/plain")


def names(entries: list[dict]) -> list[str]:
    return [e["name"] for e in entries]


# --- the image ----------------------------------------------------------------------------------


def test_the_image_is_small_and_holds_no_build_or_test_tools():
    size = image_bytes(IMAGE)
    assert size <= MAX_IMAGE_BYTES, f"{IMAGE} is {size / 1e6:.0f} MB"
    found = shell_output(
        IMAGE,
        "find /opt/venv -type d -name tests | head -3;"
        " python -c 'import pip' 2>/dev/null && echo pip;"
        " python -c 'import setuptools' 2>/dev/null && echo setuptools;"
        " python -c 'import torch' 2>/dev/null && echo torch; true",
    )
    assert found == "", found


# --- the container --------------------------------------------------------------------------------


def test_the_container_is_read_only_runs_as_non_root_and_turns_healthy(container):
    state = container.inspect()
    assert state["HostConfig"]["ReadonlyRootfs"] is True
    assert state["Config"]["User"].split(":")[0] == UID
    assert container.exec("id", "-u").stdout.strip() == UID
    for path in ("/app/written", "/opt/venv/written", "/written"):
        result = container.exec("touch", path)
        assert result.returncode != 0 and "Read-only file system" in result.stderr, path
    # the styles volume is the one place it writes
    assert container.exec("touch", f"{STYLES_DIR}/.probe").returncode == 0
    assert container.exec("rm", f"{STYLES_DIR}/.probe").returncode == 0
    container.wait_health("healthy")


def test_health_models_styles_and_preview_answer(client, styles):
    for path in ("/healthz", "/readyz", "/v2/health/live", "/v2/health/ready"):
        assert client.get(path).status_code == 200, path
    models = client.get("/v1/models").json()
    families = {m["family"] for m in models["models"]}
    assert {"translator", "fast", "dance"} <= families, families
    assert styles["translator"] and styles["fast"] and styles["dance"], styles
    page = client.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]


def test_a_bvh_is_transferred_stylized_and_coded(client, styles):
    walk = bvh.load(FIXTURE)
    translator_style = names(styles["translator"])[0]
    r = client.post("/v1/transfer", files={"content": bvh_file()},
                    data={"style_name": translator_style, "time_warp": "false"})  # fmt: skip
    assert r.status_code == 200, r.text[:500]
    out = bvh.loads(r.text)
    assert out.skeleton.names == walk.skeleton.names
    frames = (out.num_frames, int(r.headers["x-frames"]))
    assert frames == (walk.num_frames, walk.num_frames)
    assert not np.allclose(out.lrot, walk.lrot, atol=1e-3), "the style changed nothing"

    fast_style = names(styles["fast"])[0]
    fields = {"style_name": fast_style, "time_warp": "false"}
    r = client.post("/v1/stylize", files={"content": bvh_file()}, data=fields)
    assert r.status_code == 200, r.text[:500]
    frames = bvh.loads(r.text).num_frames
    assert frames == walk.num_frames

    r = client.post("/v1/style-code", files={"style": bvh_file()})
    assert r.status_code == 200, r.text[:500]
    body = r.json()
    assert len(body["code"]) > 0 and np.all(np.isfinite(body["code"]))
    assert body["nearest"][0]["style"] in names(styles["translator"])


def test_a_glb_comes_back_as_a_glb_with_its_new_animation(client, styles):
    walk = bvh.load(FIXTURE)
    sent = character_glb(walk)
    r = client.post("/v1/transfer", files={"content": ("walk.glb", sent, GLB)},
                    data={"style_name": names(styles["translator"])[-1]})  # fmt: skip
    assert r.status_code == 200, r.text[:500]
    assert r.headers["content-type"].startswith(GLB)
    before = pygltflib.GLTF2.load_from_bytes(sent)
    after = pygltflib.GLTF2.load_from_bytes(r.content)
    assert [n.name for n in after.nodes] == [n.name for n in before.nodes]
    assert len(after.animations) == 1 and r.content != sent


def test_an_fbx_is_refused_saying_how_to_enable_it_when_the_image_lacks_the_extra(client):
    if docker("run", "--rm", IMAGE, "python", "-c", "import bpy", check=False).returncode == 0:
        pytest.skip("the image has the fbx extra: an FBX round trip belongs here")
    data = b"Kaydara FBX Binary  \x00\x1a\x00" + b"\x00" * 100
    r = client.post("/v1/stylize", files={"content": ("walk.fbx", data, "application/octet-stream")},
                    data={"style_name": "angry"})  # fmt: skip
    assert r.status_code == 415, r.text[:500]
    assert r.headers["content-type"].startswith("application/problem+json")
    assert "fbx extra" in r.json()["detail"]


def test_an_mp3_song_becomes_a_dance_as_long_as_the_song(client):
    data = encoded(song(12.0, bpm=120.0, seed=1), "MP3")
    samples, sr = audio_decode.decode(data)
    r = client.post("/v1/dance", files={"audio": ("song.mp3", data, "audio/mpeg")},
                    data={"seed": "2"})  # fmt: skip
    assert r.status_code == 200, r.text[:500]
    dance = bvh.loads(r.text)
    assert dance.num_frames == math.ceil(len(samples) / sr * 30 - 1e-9)
    assert np.all(np.isfinite(dance.lrot)) and np.ptp(dance.lrot, axis=0).max() > 0.2  # it moves


def test_metrics_count_the_requests(client):
    labels = {"endpoint": "/v1/models", "method": "GET", "status": "200"}
    before = counter(client.get("/metrics").text, "motion_http_requests", **labels)
    for _ in range(7):
        assert client.get("/v1/models").status_code == 200
    after = counter(client.get("/metrics").text, "motion_http_requests", **labels)
    assert after - before == 7


# --- registered styles on the volume ------------------------------------------------------------


def transfer_with(client, style: str) -> np.ndarray:
    r = client.post("/v1/transfer", files={"content": bvh_file()}, data={"style_name": style})
    assert r.status_code == 200, r.text[:500]
    return bvh.loads(r.text).lrot


def test_a_registered_style_is_used_and_kept_when_the_container_is_replaced(
    container, client, request
):
    walk = bvh.load(FIXTURE)
    clips = [("clips", bvh_file()), ("clips", ("walk.glb", character_glb(walk), GLB))]
    r = client.post("/v1/styles", data={"name": STYLE}, files=clips)
    assert r.status_code == 201, r.text[:500]
    listed = {e["name"]: e for e in client.get("/v1/styles").json()["translator"]}
    assert listed[STYLE]["registered"] is True, listed[STYLE]
    restyled = transfer_with(client, STYLE)

    container.remove()  # the read-only container kept nothing: only the volume can
    replacement = request.getfixturevalue("replacement")
    with httpx.Client(base_url=replacement.url, timeout=120) as again:
        listed = {e["name"]: e for e in again.get("/v1/styles").json()["translator"]}
        assert listed.get(STYLE, {}).get("registered") is True, listed.keys()
        np.testing.assert_allclose(transfer_with(again, STYLE), restyled, atol=1e-3)
        assert again.delete(f"/v1/styles/{STYLE}").status_code == 204
        assert again.post("/v1/transfer", files={"content": bvh_file()},
                          data={"style_name": STYLE}).status_code == 404  # fmt: skip


# --- shutdown ------------------------------------------------------------------------------------


def test_sigterm_during_a_long_request_completes_it_and_exits_zero(replacement):
    box = replacement
    data = encoded(song(180.0, bpm=110.0, seed=4), "MP3")
    result: dict = {}

    def long_request() -> None:
        try:
            result["response"] = httpx.post(
                box.url + "/v1/dance",
                files={"audio": ("song.mp3", data, "audio/mpeg")},
                data={"seed": "1"},
                timeout=120,
            )
        except httpx.HTTPError as exc:
            result["error"] = exc

    thread = threading.Thread(target=long_request)
    thread.start()
    deadline = time.monotonic() + 60
    while gauge(httpx.get(box.url + "/metrics").text, "motion_inferences_in_flight") < 1:
        assert time.monotonic() < deadline and thread.is_alive(), "never in flight"
        time.sleep(0.05)
    docker("kill", "--signal", "TERM", box.name)
    assert thread.is_alive(), "the request ended before the signal: make it longer"
    thread.join(120)
    assert "error" not in result, f"{result.get('error')!r}\n{box.logs()}"
    response = result["response"]
    assert response.status_code == 200, response.text[:500]
    assert bvh.loads(response.text).num_frames >= 180 * 30
    exit_code = docker("wait", box.name, timeout=90).stdout.strip()
    assert exit_code == "0", box.logs()

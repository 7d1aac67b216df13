"""The image with the fbx extra (``motion-style:fbx``, ``make image-fbx``): Blender as a Python
module in a read-only container running as uid 10001, reading and writing FBX. Built and run
by ``make image-test``; skips where that image is not built."""

from __future__ import annotations

import httpx
import pytest

from tests.fbx_files import blender_reads, make_fbx_files, require_bpy
from tests.image.containers import (
    FBX_IMAGE,
    REASON,
    UID,
    docker,
    image_bytes,
    serving,
    shell_output,
    unique,
)
from tests.rigs import FIXTURE

MAX_IMAGE_BYTES = 1.7e9  # docker's "MB": the slim image's 0.62 GB and Blender's 0.94 GB
OCTET = "application/octet-stream"

FBX_REASON = REASON or (
    None
    if docker("image", "inspect", FBX_IMAGE, check=False).returncode == 0
    else f"the image {FBX_IMAGE} is not built (make image-fbx)"
)
pytestmark = pytest.mark.skipif(FBX_REASON is not None, reason=FBX_REASON or "")


@pytest.fixture(scope="module")
def container():
    volume = unique("motion-style-test-styles")
    docker("volume", "create", volume)
    try:
        with serving(volume, image=FBX_IMAGE) as box:
            yield box
    finally:
        docker("volume", "rm", "-f", volume, check=False)


def test_the_fbx_image_holds_blender_and_no_build_or_test_tools():
    size = image_bytes(FBX_IMAGE)
    assert size <= MAX_IMAGE_BYTES, f"{FBX_IMAGE} is {size / 1e6:.0f} MB"
    found = shell_output(
        FBX_IMAGE,
        "python -c 'import bpy' || echo no-bpy;"
        " python -c 'import pip' 2>/dev/null && echo pip;"
        " python -c 'import torch' 2>/dev/null && echo torch; true",
    )
    assert found == "", found


def test_a_read_only_fbx_container_transfers_an_fbx_character(container, tmp_path):
    require_bpy()  # the character is made, and the answer read, by Blender on this machine
    state = container.inspect()
    assert state["HostConfig"]["ReadonlyRootfs"] and state["Config"]["User"].startswith(UID)
    character = make_fbx_files(FIXTURE, tmp_path)["character"]
    with httpx.Client(base_url=container.url, timeout=180) as client:
        r = client.post(
            "/v1/transfer",
            files={"content": ("walk.fbx", character.read_bytes(), OCTET)},
            data={"style_name": "elderly", "time_warp": "false"},
        )
    assert r.status_code == 200, r.text[:500]
    assert r.headers["content-disposition"].endswith('.fbx"')
    answer = tmp_path / "answer.fbx"
    answer.write_bytes(r.content)
    sent, got = blender_reads([character, answer], tmp_path)
    for key in ("bones", "meshes", "skinned", "materials"):
        assert got[key] == sent[key], key
    ((start, stop),), ((sent_start, sent_stop),) = got["actions"].values(), sent["actions"].values()
    assert stop - start == pytest.approx(sent_stop - sent_start, abs=0.01)  # time_warp=false

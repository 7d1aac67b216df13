"""The Blender add-on in headless Blender (Debian's 3.4, ``blender -b``) against the real
service, which needs an API key: installed from the zip ``make blender-addon`` builds, it
restyles an imported BVH's action into a new action on the same armature, named after the
style, keeping the original, and the new action performs exactly the service's answer;
with "Keep timing" it is as long as the original. The key comes from the add-on's
preferences (after a refusal without it) or ``$MOTION_API_KEY``, and the saved .blend file
does not hold it."""

from __future__ import annotations

import json
import os
import subprocess

import httpx
import numpy as np
import pytest

from clients import addon_zip
from motion import bvh
from motion import kinematics as K
from service import api_keys
from tests.gltf_files import BLENDER, REPO, blender_run
from tests.rigs import bind_pose_first, load_fixture
from tests.server import ServerProcess

DRIVER = REPO / "tests" / "blender" / "addon_driver.py"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """The service with keys on, and the key of ``blender`` (scope ``use``)."""
    if BLENDER is None:
        pytest.skip("Blender is not installed (apt-get install blender python3-numpy)")
    folder = tmp_path_factory.mktemp("addon-server")
    key = api_keys.add_key(folder / "api-keys", "blender", frozenset({"use"}))
    env = {"MOTION_API_KEYS_FILE": str(folder / "api-keys")}
    with ServerProcess(env=env, log_path=folder / "server.log") as running:
        yield running, key


def run_driver(package, clip, url: str, key: str, key_source: str, out) -> str:
    """The driver in headless Blender, restyling ``clip`` "elderly"; Blender's output."""
    env = {k: v for k, v in os.environ.items() if k != "MOTION_API_KEY"}
    env["BLENDER_USER_SCRIPTS"] = str(out / "blender-user")
    env["MOTION_STYLE_TEST_KEY" if key_source == "preferences" else "MOTION_API_KEY"] = key
    result = subprocess.run(
        [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python",
         str(DRIVER), "--", str(package), str(clip), url, "elderly", "1.0", str(out),
         key_source],
        capture_output=True, text=True, timeout=180, env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    return result.stdout


@pytest.mark.parametrize(("source", "key_source"), [("bvh", "preferences"), ("glb", "environment")])
def test_addon_restyles_an_action_in_headless_blender(server, source, key_source, tmp_path):
    """``bvh``: an armature Blender's BVH importer built; ``glb``: one its glTF importer
    built from Blender's GLB of the same walk (other bone orientations, a skinned mesh)."""
    server, key = server
    package = addon_zip.build(tmp_path / "motion_style.zip")
    clip = tmp_path / "walk.bvh"
    bvh.save(load_fixture().slice(0, 60), clip)
    if source == "glb":
        blender_run("export", str(clip), str(tmp_path / "walk.glb"))
        clip = tmp_path / "walk.glb"
    run_driver(package, clip, server.url, key, key_source, tmp_path)
    # what the service makes of the action Blender exported
    sent = (tmp_path / "before.bvh").read_bytes()
    answer = httpx.post(
        server.url + "/v1/transfer", files={"content": ("walk.bvh", sent)},
        data={"style_name": "elderly", "strength": "1.0"}, timeout=120,
        headers={"Authorization": f"Bearer {key}"},
    )  # fmt: skip
    assert answer.status_code == 200, answer.text
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["addon_file"].startswith(str(tmp_path / "blender-user"))  # from the zip
    assert report["panel"] and report["refresh"] == ["FINISHED"]
    assert "elderly" in report["styles"] and "angry" in report["styles"]
    assert report["transfer"] == ["FINISHED"]

    expected = bvh.loads(answer.content)
    frames = int(answer.headers["X-Frames"])
    assert expected.num_frames == frames != 60  # elderly is slower: the time warp stretches it
    new, original = report["active_action"], report["original"]
    assert new != original and report["actions"] == sorted([original, new])
    assert new == f"{original}.elderly"  # named after the style
    first, last = report["active_range"]
    assert last - first + 1 == frames and report["keys"] == frames
    assert report["original_kept"] and report["original_fake_user"]
    assert report["original_range_after"] == report["original_range"]
    if source == "bvh":
        assert report["original_range"] == [1.0, 60.0]
    assert report["original_curves_after"] == report["original_curves"]
    assert report["objects_after"] == report["objects_before"]  # no scratch armature left
    assert "404" in report["bad_style"] and report["action_after_bad_style"] == new
    if key_source == "preferences":  # refused without it, and told where a key goes
        assert "401" in report["refresh_without_key"]
        assert "preferences" in report["refresh_without_key"]
    scene = (tmp_path / "scene.blend").read_bytes()
    assert new.encode() in scene  # the saved file holds the new action, not the key
    assert key.encode() not in scene and key.removeprefix("msk_")[:12].encode() not in scene
    # "Keep timing": no time warp, the new action as long as the original
    assert report["kept_timing"] == ["FINISHED"]
    assert report["kept_timing_range"] == report["original_range"]
    assert report["kept_timing_action"].startswith(f"{original}.elderly")

    # the new action performs the service's answer: same joint positions every frame
    performed = bvh.load(tmp_path / "after.bvh")
    assert performed.skeleton.names == expected.skeleton.names
    height = expected.skeleton.height()
    error = np.abs(K.global_positions(performed) - K.global_positions(expected)).max()
    assert error < 1e-4 * height, error


def test_the_services_warnings_show_in_blenders_reports(server, tmp_path):
    """An action whose first frame is the bind pose: the service gives that frame back
    unrestyled and says so, and the add-on reports it as a warning (``X-Warnings``)."""
    server, key = server
    package = addon_zip.build(tmp_path / "motion_style.zip")
    clip = tmp_path / "bound.bvh"
    bvh.save(bind_pose_first(load_fixture().slice(0, 60)), clip)
    said = run_driver(package, clip, server.url, key, "environment", tmp_path)
    warned = [line for line in said.splitlines() if line.startswith("Warning: Motion Style: ")]
    assert any("reference pose" in line for line in warned), said[-3000:]
    assert json.loads((tmp_path / "report.json").read_text())["transfer"] == ["FINISHED"]

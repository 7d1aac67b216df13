"""FBX in and out of the service (the ``fbx`` extra: Blender as a Python module, run in a
pool of worker processes), against the real app and the shipped models.

The files are Blender 4.2's own FBX exports, made here from the CMU fixture: the armature
Blender imports from the BVH (``bare``) and that armature with a skinned body and a
material (``character``). They go through /v1/transfer, /v1/stylize, /v1/dance
(``skeleton``) and /v1/styles (``clips``); Blender's FBX importer reads every answer with
the same bone names, meshes and materials, and (``time_warp=false``) an animation of the same
length. Without bpy these skip, except the 415 that says how to enable FBX.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from motion import bvh
from motion import kinematics as K
from service import fbx
from service.config import Settings
from tests.api.helpers import assert_problem
from tests.fbx_files import blender_reads, make_fbx_files, require_bpy
from tests.rigs import FIXTURE
from tests.server import ServerProcess
from training.songs import encoded, song

OCTET = "application/octet-stream"
SONG_SECONDS = 2.0


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("fbx")
    return {name: path.read_bytes() for name, path in make_fbx_files(FIXTURE, folder).items()}


@pytest.fixture(scope="module")
def answers(tmp_path_factory):
    """FBX answers saved by the tests (name -> path), read by Blender all at once."""
    return tmp_path_factory.mktemp("answers"), {}


def keep(answers, name: str, data: bytes) -> None:
    folder, saved = answers
    path = folder / f"{name}.fbx"
    path.write_bytes(data)
    saved[name] = path


def post(client, path: str, files: dict, query: str = "", **fields):
    return client.post(path + query, files=files, data=fields)


@pytest.mark.parametrize(
    ("path", "fields"),
    [
        ("/v1/transfer", {"style_name": "elderly"}),
        ("/v1/stylize", {"style_name": "angry"}),
    ],
)
def test_an_fbx_character_comes_back_as_its_fbx_with_the_new_animation(
    shared_client, files, answers, path, fields
):
    r = post(shared_client, path, {"content": ("walk.fbx", files["character"], OCTET)},
             time_warp="false", **fields)  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == OCTET
    assert r.headers["content-disposition"].endswith('.fbx"')
    assert r.content.startswith(b"Kaydara FBX Binary")
    walk = bvh.load(FIXTURE)
    assert int(r.headers["x-frames"]) == walk.num_frames
    keep(answers, path.rsplit("/", 1)[1], r.content)

    # The FBX answer moves as the BVH answer to the same request on the BVH the character
    # was made from does, and not as the input did.
    result = fbx.read(r.content, workers=1, timeout=60, max_frames=1000).motion
    r_bvh = post(shared_client, path, {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")},
                 time_warp="false", **fields)  # fmt: skip
    ref = bvh.loads(r_bvh.text)
    index = [result.skeleton.names.index(n) for n in ref.skeleton.names]
    height = walk.skeleton.height()
    out = K.global_positions(result)[:, index]
    gap = np.abs(out - K.global_positions(ref)).max()
    assert gap < 0.01 * height, gap / height
    moved = np.abs(out - K.global_positions(walk)).max()
    assert moved > 0.02 * height


def test_an_fbx_style_clip_and_a_bare_fbx_armature_as_content(shared_client, files, answers):
    r = post(shared_client, "/v1/transfer",
             {"content": ("walk.fbx", files["bare"], OCTET),
              "style": ("style.fbx", files["character"], OCTET)}, time_warp="false")  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.content.startswith(b"Kaydara FBX Binary")
    keep(answers, "bare", r.content)
    r = post(shared_client, "/v1/style-code", {"style": ("style.fbx", files["character"], OCTET)})
    fbx_code = np.array(r.json()["code"])
    r = post(shared_client, "/v1/style-code",
             {"style": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")})  # fmt: skip
    bvh_code = np.array(r.json()["code"])
    assert np.abs(fbx_code - bvh_code).max() < 0.05 * np.abs(bvh_code).max()


def test_a_dance_on_an_fbx_skeleton_is_that_fbx_dancing_for_the_whole_song(
    shared_client, files, answers
):
    wav = encoded(song(SONG_SECONDS), "WAV")
    r = post(shared_client, "/v1/dance",
             {"audio": ("song.wav", wav, "audio/wav"),
              "skeleton": ("rig.fbx", files["character"], OCTET)}, fps="24", seed="1")  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.headers["content-disposition"].endswith('.fbx"') and r.headers["x-fps"] == "24"
    frames = int(r.headers["x-frames"])
    assert frames == int(np.ceil(SONG_SECONDS * 24 - 1e-9))
    keep(answers, "dance", r.content)
    dance = fbx.read(r.content, workers=1, timeout=60, max_frames=1000).motion
    assert dance.num_frames == frames and dance.fps == pytest.approx(24.0)


def test_blender_reads_every_answer_with_the_same_bones_meshes_and_length(files, answers):
    folder, saved = answers
    if len(saved) < 4:
        pytest.skip("the tests that make the answers did not all run")
    names = sorted(saved)
    inputs = [folder / "in_character.fbx", folder / "in_bare.fbx"]
    inputs[0].write_bytes(files["character"])
    inputs[1].write_bytes(files["bare"])
    reads = blender_reads([*inputs, *(saved[n] for n in names)], folder)
    character, bare = reads[0], reads[1]
    assert character["skinned"] == ["Body"] and character["meshes"]["Body"] > 100
    assert bare["meshes"] == {}
    length = np.diff(next(iter(character["actions"].values())))[0]
    for name, read in zip(names, reads[2:], strict=True):
        source = bare if name == "bare" else character
        assert read["bones"] == source["bones"], name
        assert read["meshes"] == source["meshes"], name
        assert read["skinned"] == source["skinned"], name
        assert read["materials"] == source["materials"], name
        (action,) = read["actions"].values()
        if name == "dance":
            assert read["fps"] == pytest.approx(24.0)
            assert action[1] - action[0] == pytest.approx(np.ceil(SONG_SECONDS * 24) - 1, abs=0.01)
        else:
            assert read["fps"] == pytest.approx(source["fps"], rel=1e-6), name
            assert action[1] - action[0] == pytest.approx(length, abs=0.01), name


def test_format_asks_for_bvh_or_json_of_an_fbx_and_fbx_needs_an_fbx(shared_client, files):
    content = {"content": ("walk.fbx", files["character"], OCTET)}
    walk = bvh.load(FIXTURE)
    r = post(shared_client, "/v1/stylize", content, "?format=bvh", style_name="proud")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    assert set(walk.skeleton.names) <= set(bvh.loads(r.text).skeleton.names)
    r = post(shared_client, "/v1/stylize", content, "?format=json", style_name="proud")
    assert r.status_code == 200 and r.json()["source_format"] == "fbx"
    r = post(shared_client, "/v1/stylize", content, "?format=glb", style_name="proud")
    assert "the clip is FBX" in assert_problem(r, 400, "invalid-request")["detail"]
    r = post(shared_client, "/v1/stylize",
             {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}, "?format=fbx",
             style_name="proud")  # fmt: skip
    body = assert_problem(r, 400, "invalid-request")
    assert body["field"] == "format" and "the clip is BVH" in body["detail"]


def test_an_fbx_registered_style(shared_client, files):
    r = shared_client.post(
        "/v1/styles",
        data={"name": "fbx-walk"},
        files=[("clips", ("a.fbx", files["character"], OCTET)),
               ("clips", ("b.fbx", files["bare"], OCTET))],
    )  # fmt: skip
    assert r.status_code == 201, r.text
    try:
        r = post(shared_client, "/v1/transfer",
                 {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")},
                 style_name="fbx-walk")  # fmt: skip
        assert r.status_code == 200, r.text
    finally:
        shared_client.delete("/v1/styles/fbx-walk")


def test_broken_and_unusable_fbx_files_are_problems(make_client, files, tmp_path):
    require_bpy()
    client = make_client(Settings(max_frames=40))
    send = lambda data: post(client, "/v1/stylize", {"content": ("x.fbx", data, OCTET)},  # noqa: E731
                             style_name="angry")  # fmt: skip
    body = assert_problem(send(files["character"]), 413, "too-large")
    assert body["limit"] == 40 and "max_frames" in body["detail"]
    body = assert_problem(send(files["character"][:4000]), 400, "invalid-input")
    assert "Blender could not read the FBX file" in body["detail"] and "/tmp" not in body["detail"]
    body = assert_problem(send(b"; FBX 7.4.0 project file\n; ----\n"), 400, "invalid-input")
    assert "binary" in body["detail"]


def test_a_blender_that_hangs_is_a_504_and_is_replaced(files):
    require_bpy()
    pool = fbx.start(1)
    with pytest.raises(fbx.Timeout):
        pool.call("read", files["character"], 0.001, max_frames=1000)
    motion = fbx.read(files["character"], workers=1, timeout=60, max_frames=1000).motion
    assert motion.num_frames == bvh.load(FIXTURE).num_frames


@pytest.mark.parametrize("how", ["no bpy", "fbx_workers=0"])
def test_without_the_extra_an_fbx_is_a_415_that_says_how_to_enable_it(
    make_client, monkeypatch, how
):
    if how == "no bpy":
        monkeypatch.setattr(fbx, "installed", lambda: False)
        client = make_client()
    else:
        client = make_client(Settings(fbx_workers=0))
    data = fbx.FBX_MAGIC + b"\x00" * 100
    r = post(client, "/v1/stylize", {"content": ("walk.fbx", data, OCTET)}, style_name="angry")
    body = assert_problem(r, 415, "unsupported-media-type")
    assert "fbx extra" in body["detail"] and "pip install 'motion-style[fbx]'" in body["detail"]
    assert "MOTION_FBX_WORKERS" in body["detail"]


def test_a_replica_reports_ready_only_once_its_blender_workers_are_warm(tmp_path):
    """Blender starts after the models and before readiness: a replica never takes traffic
    while its workers boot beside the requests, and the first FBX finds them warm."""
    require_bpy()
    log_path = tmp_path / "server.log"
    with ServerProcess(env={"MOTION_FBX_WORKERS": "2"}, log_path=log_path) as server:
        log = server.log()  # as it stood at the first 200 from /readyz
        ready = re.search(r"FBX: (\d) of 2 Blender workers ready", log)
        assert ready is not None and ready.group(1) == "2", log[-3000:]
        assert log.index("models ready") < ready.start()

"""glTF binary in and out of the service, against the real app and the shipped models.

A GLB (or a ``.gltf`` with embedded buffers) works wherever a BVH does: ``content``,
``style`` and the dance's ``skeleton``, told apart by its bytes. The answer is the file
sent with the new animation in place of the old one (every node, mesh, skin and material
kept, the same names), unless ``?format=`` asks for BVH or JSON. Characters are built here
with pygltflib from the CMU fixture; the round trip of GLBs that Blender exports is read
back by three.js's GLTFLoader (node) and by Blender's importer where they are installed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from motion import bvh, gltf
from motion import kinematics as K
from service.config import Settings
from tests.api.helpers import assert_problem
from tests.gltf_files import (
    blender_run,
    character_glb,
    embedded_gltf_bytes,
    three_js_name,
    three_js_summary,
)
from tests.rigs import FIXTURE
from training.songs import encoded, song

GLB = "model/gltf-binary"
SONG_SECONDS = 3.0


@pytest.fixture(scope="module")
def walk():
    return bvh.load(FIXTURE)


@pytest.fixture(scope="module")
def walk_glb(walk) -> bytes:
    return character_glb(walk)


@pytest.fixture(scope="module")
def wav() -> bytes:
    return encoded(song(SONG_SECONDS), "WAV")


def post(client, path: str, files: dict, query: str = "", **fields):
    return client.post(path + query, files=files, data=fields)


def document(data: bytes) -> pygltflib.GLTF2:
    return pygltflib.GLTF2.load_from_bytes(data)


def kept(before: pygltflib.GLTF2, after: pygltflib.GLTF2, animations: bool = True) -> None:
    """Every node, mesh, skin and material of ``before`` is in ``after`` as it was (and
    the animations' names)."""
    old, new = json.loads(before.gltf_to_json()), json.loads(after.gltf_to_json())
    for field in ("nodes", "meshes", "skins", "materials", "scenes"):
        assert new.get(field) == old.get(field), field
    if animations:
        assert [a.name for a in after.animations] == [a.name for a in before.animations]


def animation_seconds(doc: pygltflib.GLTF2) -> tuple[float, int]:
    """The first animation's last key time and key count (as a player reads them)."""
    inputs = {s.input for s in doc.animations[0].samplers}
    return max(doc.accessors[i].max[0] for i in inputs), max(doc.accessors[i].count for i in inputs)


@pytest.mark.parametrize(
    ("path", "fields"),
    [("/v1/transfer", {"style_name": "elderly"}), ("/v1/stylize", {"style_name": "angry"})],
)
def test_a_glb_content_comes_back_as_its_glb_with_the_new_animation(
    shared_client, walk, walk_glb, path, fields
):
    r = post(shared_client, path, {"content": ("walk.glb", walk_glb, GLB)}, **fields)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == GLB
    assert r.headers["content-disposition"].endswith('.glb"')
    frames, fps = int(r.headers["x-frames"]), float(r.headers["x-fps"])
    assert fps == 30.0
    after, before = document(r.content), document(walk_glb)
    kept(before, after)
    last, keys = animation_seconds(after)
    assert keys == frames and last == pytest.approx((frames - 1) / fps, abs=1e-4)

    # The answer moves as the BVH answer to the same request does (the GLB reads as the
    # fixture less its End Sites), and not as the input did.
    out = gltf.loads(r.content)
    assert out.skeleton.names == walk.skeleton.names and out.num_frames == frames
    r_bvh = post(shared_client, path, {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")},
                 **fields)  # fmt: skip
    assert r_bvh.status_code == 200 and r_bvh.headers["content-type"].startswith("text/plain")
    ref = bvh.loads(r_bvh.text)
    assert ref.num_frames == frames
    height = walk.skeleton.height()
    gap = np.abs(K.global_positions(out) - K.global_positions(ref)).max()
    assert gap < 0.01 * height, gap
    moved = np.abs(K.global_positions(out)[: walk.num_frames] - K.global_positions(walk)[:frames])
    assert moved.max() > 0.02 * height


def test_format_asks_for_bvh_or_json_of_a_glb_content(shared_client, walk, walk_glb):
    files = {"content": ("walk.glb", walk_glb, GLB)}
    r = post(shared_client, "/v1/transfer", files, "?format=bvh", style_name="proud")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
    assert r.headers["content-disposition"].endswith('.bvh"')
    assert bvh.loads(r.text).skeleton.names == walk.skeleton.names
    r = post(shared_client, "/v1/transfer", files, "?format=json", style_name="proud")
    body = r.json()
    assert r.status_code == 200 and body["source_format"] == "glb"
    result = bvh.loads(body["bvh"])
    assert result.skeleton.names == walk.skeleton.names and result.num_frames == body["frames"]
    assert body["rig"]["method"] == "names"
    r = post(shared_client, "/v1/transfer", files, "?format=glb", style_name="proud")
    assert r.status_code == 200 and r.headers["content-type"] == GLB


def test_format_glb_without_a_gltf_file_to_write_into_is_a_400(shared_client, wav):
    r = post(shared_client, "/v1/transfer",
             {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}, "?format=glb",
             style_name="proud")  # fmt: skip
    body = assert_problem(r, 400, "invalid-request")
    assert body["field"] == "format" and "the clip is BVH" in body["detail"]
    r = post(shared_client, "/v1/stylize",
             {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}, "?format=glb",
             style_name="angry")  # fmt: skip
    assert assert_problem(r, 400)["field"] == "format"
    r = post(shared_client, "/v1/dance", {"audio": ("song.wav", wav, "audio/wav")}, "?format=glb")
    body = assert_problem(r, 400, "invalid-request")
    assert "no glTF file was sent" in body["detail"]


@pytest.mark.parametrize(
    "media_type", ["application/octet-stream", "text/plain", "", "model/gltf+json"]
)
def test_the_bytes_say_glb_whatever_the_media_type(shared_client, walk_glb, media_type):
    r = post(shared_client, "/v1/stylize", {"content": ("take", walk_glb, media_type)},
             style_name="angry")  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == GLB


def test_an_embedded_gltf_works_like_its_glb_and_comes_back_as_glb(shared_client, walk):
    doc = pygltflib.GLTF2.load_from_bytes(character_glb(walk))
    text = embedded_gltf_bytes(doc)
    assert text.lstrip().startswith(b"{")
    r = post(shared_client, "/v1/transfer", {"content": ("walk.gltf", text, "model/gltf+json")},
             style_name="elderly")  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == GLB
    assert gltf.loads(r.content).skeleton.names == walk.skeleton.names


def test_a_glb_style_clip_codes_like_its_bvh(shared_client, walk_glb):
    codes = []
    for name, data, media in (("walk.glb", walk_glb, GLB),
                              ("walk.bvh", FIXTURE.read_bytes(), "text/plain")):  # fmt: skip
        r = post(shared_client, "/v1/style-code", {"style": (name, data, media)})
        assert r.status_code == 200, r.text
        codes.append(np.array(r.json()["code"]))
    assert np.abs(codes[0] - codes[1]).max() < 0.05 * np.abs(codes[1]).max()
    r = post(shared_client, "/v1/transfer",
             {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain"),
              "style": ("walk.glb", walk_glb, GLB)})  # fmt: skip
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")


@pytest.mark.parametrize("animated", [True, False])
def test_a_dance_on_a_glb_skeleton_is_that_glb_dancing_for_the_whole_song(
    shared_client, walk, wav, animated
):
    rig = character_glb(walk, animated=animated)
    r = post(shared_client, "/v1/dance",
             {"audio": ("song.wav", wav, "audio/wav"), "skeleton": ("rig.glb", rig, GLB)},
             fps="24", seed="1")  # fmt: skip
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == GLB and r.headers["x-fps"] == "24"
    frames = int(r.headers["x-frames"])
    assert frames == int(np.ceil(SONG_SECONDS * 24 - 1e-9))
    after, before = document(r.content), document(rig)
    kept(before, after, animations=animated)
    last, keys = animation_seconds(after)
    assert keys == frames and last == pytest.approx((frames - 1) / 24, abs=1e-4)
    dance = gltf.loads(r.content)
    assert dance.skeleton.names == walk.skeleton.names
    assert np.ptp(K.global_positions(dance)[:, 0], axis=0).max() > 0.01 * walk.skeleton.height()


def test_broken_and_unusable_glb_files_are_problems(make_client, walk, walk_glb):
    client = make_client(Settings(max_frames=40))
    files = lambda data: {"content": ("walk.glb", data, GLB)}  # noqa: E731
    body = assert_problem(post(client, "/v1/stylize", files(walk_glb[:300]), style_name="angry"),
                          400, "invalid-input")  # fmt: skip
    assert "glTF" in body["detail"]
    body = assert_problem(post(client, "/v1/stylize", files(walk_glb), style_name="angry"),
                          413, "too-large")  # fmt: skip
    assert body["limit"] == 40 and body["limit_name"] == "max_frames"
    still = character_glb(walk.slice(0, 10), animated=False)
    body = assert_problem(post(client, "/v1/stylize", files(still), style_name="angry"),
                          422, "unusable-input")  # fmt: skip
    assert "no animation" in body["detail"]
    r = post(client, "/v1/stylize", {"content": ("walk.glb", walk_glb, "image/png")},
             style_name="angry")  # fmt: skip
    assert "glTF" in assert_problem(r, 415, "unsupported-media-type")["detail"]


# --- GLBs that Blender exports, read back by three.js and Blender ------------------------


@pytest.fixture(scope="module")
def blender_round_trip(shared_client, tmp_path_factory, wav) -> dict[str, tuple[Path, Path]]:
    """name -> (the GLB Blender exported from the CMU walk, the service's answer): through
    /v1/transfer, /v1/stylize and /v1/dance (as its skeleton)."""
    folder = tmp_path_factory.mktemp("blender-service")
    clip = bvh.load(FIXTURE)
    bvh.save(clip, folder / "walk.bvh")
    blender_run("export", str(folder / "walk.bvh"), str(folder / "walk.glb"))
    glb = (folder / "walk.glb").read_bytes()
    requests = {
        "transfer": ("/v1/transfer", {"content": ("walk.glb", glb, GLB)}, {"style_name": "elderly"}),
        "stylize": ("/v1/stylize", {"content": ("walk.glb", glb, GLB)}, {"style_name": "angry"}),
        "dance": ("/v1/dance", {"audio": ("song.wav", wav, "audio/wav"),
                                "skeleton": ("walk.glb", glb, GLB)}, {"fps": "24"}),
    }  # fmt: skip
    out = {}
    for name, (path, files, fields) in requests.items():
        r = post(shared_client, path, files, **fields)
        assert r.status_code == 200, r.text
        assert r.headers["content-type"] == GLB
        (folder / f"{name}.glb").write_bytes(r.content)
        out[name] = (folder / "walk.glb", folder / f"{name}.glb")
    return out


def expected_seconds(answer: Path) -> float:
    """How long the answer's animation plays: its frames at its rate."""
    motion = gltf.load(answer)
    return (motion.num_frames - 1) / motion.fps


def start_time(original: Path) -> float:
    """When the original animation starts (Blender's starts at its frame 1): the written
    one starts there too."""
    doc = document(original.read_bytes())
    return min(doc.accessors[s.input].min[0] for s in doc.animations[0].samplers)


def test_three_js_reads_every_answer_with_the_same_nodes(blender_round_trip):
    for name, (original, answer) in blender_round_trip.items():
        before, after = three_js_summary(original), three_js_summary(answer)
        assert after["nodes"] == before["nodes"], name
        assert after["skinned"] == before["skinned"] and after["materials"] == before["materials"]
        assert [a["name"] for a in after["animations"]] == [a["name"] for a in before["animations"]]
        clip = after["animations"][0]
        end = start_time(original) + expected_seconds(answer)
        assert clip["duration"] == pytest.approx(end, abs=1e-3), name
        joints = {t.rsplit(".", 1)[0] for t in clip["tracks"]}
        assert joints == {three_js_name(n) for n in gltf.load(answer).skeleton.names}
    dance = blender_round_trip["dance"][1]
    assert expected_seconds(dance) == pytest.approx(SONG_SECONDS - 1 / 24, abs=1e-3)


def test_blender_reads_every_answer_with_the_same_names(blender_round_trip, tmp_path):
    args = []
    for name, (original, answer) in blender_round_trip.items():
        args += [str(original), str(tmp_path / f"{name}.in.json")]
        args += [str(answer), str(tmp_path / f"{name}.out.json")]
    blender_run("inspect", *args)
    for name, (_, answer) in blender_round_trip.items():
        before = json.loads((tmp_path / f"{name}.in.json").read_text())
        after = json.loads((tmp_path / f"{name}.out.json").read_text())
        for field in ("objects", "meshes", "materials", "bones"):
            assert after[field] == before[field], (name, field)
        (action,) = after["actions"].values()
        first, last = action["frame_range"]
        seconds = (last - first) / after["fps"]
        assert seconds == pytest.approx(expected_seconds(answer), abs=1e-3), name

"""Registered styles (``POST /v1/styles``, ``GET``, ``DELETE /v1/styles/{name}``) against the
real app and the shipped translator: a style's code is the mean of its clips' codes, it is
listed as registered, ``style_name`` and ``style_mix`` use it, names cannot shadow shipped
styles, count and clips are limited, bad clips get the usual problems, and two apps on one
folder (two workers) see each other's styles at once; a real server restarted with two
workers uses a style registered before the restart."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np
import pytest

from motion import bvh
from motion import kinematics as K
from service.config import Settings
from service.registered_styles import RegisteredStyle
from tests.api.helpers import assert_problem
from tests.conftest import data_path
from tests.gltf_files import character_glb
from tests.rigs import FIXTURE, load_fixture
from tests.server import ServerProcess

GLB = "model/gltf-binary"


@pytest.fixture(scope="module")
def styles_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("registered-styles")


@pytest.fixture(scope="module")
def client(styles_dir):
    """The shipped models, registered styles in a folder of this module."""
    import warnings

    from service.main import create_app

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*starlette.testclient.*")
        from fastapi.testclient import TestClient

    app = create_app(Settings(styles_dir=styles_dir))
    with TestClient(app) as c:
        assert app.state.registry.wait(120) and app.state.registry.ready
        yield c


def clip_files(*clips: tuple[str, bytes]) -> list[tuple[str, tuple[str, bytes, str]]]:
    return [
        ("clips", (name, data, GLB if name.endswith(".glb") else "text/plain"))
        for name, data in clips
    ]


def register(client, name: str, *clips: tuple[str, bytes], **fields):
    return client.post("/v1/styles", data={"name": name, **fields}, files=clip_files(*clips))


def walk_clips() -> list[tuple[str, bytes]]:
    """The CMU walk, its second half, and the first half as a GLB character."""
    walk = load_fixture()
    half = walk.num_frames // 2
    return [
        ("walk.bvh", FIXTURE.read_bytes()),
        ("second_half.bvh", bvh.dumps(walk.slice(half, walk.num_frames)).encode()),
        ("first_half.glb", character_glb(walk.slice(0, half))),
    ]


def style_code(client, name: str, data: bytes) -> np.ndarray:
    media = GLB if name.endswith(".glb") else "text/plain"
    r = client.post("/v1/style-code", files={"style": (name, data, media)})
    assert r.status_code == 200, r.text
    return np.array(r.json()["code"])


def transfer(client, query: str = "", **fields):
    content = {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}
    return client.post("/v1/transfer" + query, files=content, data=fields)


def test_a_style_is_the_mean_of_its_clips_codes_and_is_used_by_name_and_in_mixes(client):
    clips = walk_clips()
    r = register(client, "studio-walk", *clips)
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["name"] == "studio-walk" and body["registered"] is True
    assert body["clips"] == 3 and body["speed"] == 1.0
    codes = np.array([style_code(client, name, data) for name, data in clips])
    assert np.abs(np.array(body["code"]) - codes.mean(axis=0)).max() < 1e-4
    assert body["spread"] == pytest.approx(
        np.linalg.norm(codes - codes.mean(axis=0), axis=1).mean(), abs=1e-3
    )
    shipped = {s["name"] for s in client.get("/v1/styles").json()["translator"]} - {"studio-walk"}
    assert len(body["nearest"]) == 5 and {n["style"] for n in body["nearest"]} <= shipped
    assert body["model"]["version"] and body["frames"] > 0

    listing = client.get("/v1/styles").json()
    assert set(listing) == {"translator", "fast", "dance"}
    mine = [s for s in listing["translator"] if s["name"] == "studio-walk"]
    assert len(mine) == 1 and mine[0]["registered"] is True and mine[0]["clips"] == 3
    assert all(s["registered"] is False for s in listing["translator"] if s is not mine[0])

    # by name it plays its code as a clip's plays: taken out from the centre of the learned
    # codes (the gain of a style clip's code), as a shipped name's code is
    r = client.post("/v1/style-code", data={"style_name": "studio-walk"})
    engine = client.app.state.registry.engines[body["model"]["name"]]
    centre = engine.codes.mean(axis=0)
    gain = engine.example_gains["style"]
    played = centre + gain * (np.array(body["code"]) - centre)
    assert gain > 1
    assert r.status_code == 200 and r.json()["code"] == pytest.approx(played.tolist(), abs=1e-5)
    assert r.json()["speed"] == 1.0

    by_name = transfer(client, "?format=json", style_name="studio-walk")
    as_mix = transfer(client, "?format=json", style_mix=json.dumps({"studio-walk": 2.0}))
    assert by_name.status_code == 200 and as_mix.status_code == 200, by_name.text
    assert by_name.json()["bvh"] == as_mix.json()["bvh"]
    mixed = transfer(client, "?format=json", style_mix=json.dumps({"studio-walk": 1, "proud": 1}))
    proud = transfer(client, "?format=json", style_name="proud")
    assert mixed.status_code == 200
    assert len({by_name.json()["bvh"], mixed.json()["bvh"], proud.json()["bvh"]}) == 3
    assert client.delete("/v1/styles/studio-walk").status_code == 204


def test_a_style_from_xias_old_clip_restyles_a_cmu_walk_as_the_clip_itself_would(client):
    old = data_path("xia", "old_13_000.bvh").read_bytes()
    r = register(client, "xia-old", ("old_13_000.bvh", old))
    assert r.status_code == 201, r.text
    walk = FIXTURE.read_bytes()
    by_name = transfer(client, style_name="xia-old", time_warp="false")
    assert by_name.status_code == 200, by_name.text
    result = bvh.loads(by_name.text)
    assert result.skeleton.names == bvh.load(FIXTURE).skeleton.names
    # Xia's old man reads as Bandai's elderly: its code lies nearest elderly's, and the walk
    # restyled by it is nearer the walk restyled "elderly" than any other shipped style's
    nearest = r.json()["nearest"]
    assert (
        nearest[0]["style"] == "elderly" and nearest[0]["distance"] < 0.5 * nearest[1]["distance"]
    )
    poses = K.global_positions(result)
    gaps = {}
    for other in {s["name"] for s in client.get("/v1/styles").json()["translator"]} - {"xia-old"}:
        shipped = bvh.loads(transfer(client, style_name=other, time_warp="false").text)
        gaps[other] = float(np.abs(K.global_positions(shipped) - poses).mean())
    assert min(gaps, key=gaps.get) == "elderly", sorted(gaps.items(), key=lambda kv: kv[1])[:3]
    # ... and it is what the clip itself makes of the walk as a style clip
    content = {"content": ("walk.bvh", walk, "text/plain"), "style": ("old.bvh", old, "text/plain")}
    as_clip = client.post("/v1/transfer", files=content, data={"time_warp": "false"})
    gap = K.global_positions(bvh.loads(as_clip.text)) - K.global_positions(result)
    assert np.abs(gap).max() < 1e-3 * result.skeleton.height()
    assert client.delete("/v1/styles/xia-old").status_code == 204


@pytest.mark.parametrize(
    ("name", "status", "words"),
    [
        ("Walk Cycle", 400, "not allowed"),
        ("-lead", 400, "not allowed"),
        ("x" * 49, 400, "not allowed"),
        ("elderly", 409, "shipped translator style"),
        ("angry", 409, "shipped"),
        ("waltz", 409, "shipped dance style"),
    ],
)
def test_names_are_checked_and_cannot_shadow_shipped_styles(client, name, status, words):
    r = register(client, name, ("walk.bvh", FIXTURE.read_bytes()))
    body = assert_problem(r, status)
    assert words in body["detail"]


def test_a_name_is_registered_once_and_deleted_once(client, styles_dir):
    clip = ("walk.bvh", FIXTURE.read_bytes())
    assert register(client, "twice", clip).status_code == 201
    assert (styles_dir / "twice.json").is_file()
    body = assert_problem(register(client, "twice", clip), 409, "conflict")
    assert "registered already" in body["detail"]
    named = [transfer(client, style_name=name) for name in ("twice", "Twice")]  # any case
    assert named[0].status_code == named[1].status_code == 200 and named[0].text == named[1].text
    assert client.delete("/v1/styles/twice").status_code == 204
    assert not (styles_dir / "twice.json").exists()
    assert_problem(client.delete("/v1/styles/twice"), 404, "not-found")
    body = assert_problem(transfer(client, style_name="twice"), 404, "not-found")
    assert "twice" in body["detail"]
    body = assert_problem(client.delete("/v1/styles/elderly"), 409, "conflict")
    assert "cannot be deleted" in body["detail"]
    assert client.post("/v1/style-code", data={"style_name": "elderly"}).status_code == 200


def test_bad_clips_get_the_usual_problems_naming_the_clip(client):
    good = ("walk.bvh", FIXTURE.read_bytes())
    broken = ("broken.bvh", FIXTURE.read_bytes()[:400])
    body = assert_problem(register(client, "bad", good, broken), 400, "invalid-input")
    assert body["detail"].startswith("clip 2 (broken.bvh): ") and "line" in body
    glb = ("broken.glb", character_glb(load_fixture())[:500])
    assert_problem(register(client, "bad", glb), 400, "invalid-input")
    r = client.post("/v1/styles", data={"name": "bad"},
                    files=[("clips", ("a.png", b"\x89PNG....", "image/png"))])  # fmt: skip
    assert_problem(r, 415, "unsupported-media-type")
    tail = (
        b"HIERARCHY\nROOT Pelvis\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition"
        b" Zrotation Xrotation Yrotation\n JOINT Tail\n {\n  OFFSET 0 -10 0\n  CHANNELS 3"
        b" Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -5 0\n  }\n }\n}\n"
        b"MOTION\nFrames: 2\nFrame Time: 0.0333333\n" + b"0 0 0 0 0 0 0 0 0\n" * 2
    )
    assert_problem(register(client, "bad", good, ("tail.bvh", tail)), 422, "unusable-input")
    assert_problem(client.post("/v1/styles", data={"name": "bad"}), 400, "invalid-request")
    body = assert_problem(register(client, "bad", good, mapping="[1]"), 400, "invalid-request")
    assert body["field"] == "mapping"
    assert_problem(register(client, "bad", good, speed="3"), 400, "invalid-request")
    assert "bad" not in {s["name"] for s in client.get("/v1/styles").json()["translator"]}


def test_a_style_coded_by_another_model_version_is_refused_until_registered_again(
    client, styles_dir
):
    proud = client.post("/v1/style-code", data={"style_name": "proud"}).json()
    stale = RegisteredStyle(
        name="stale", code=np.zeros(len(proud["code"]), np.float32), velocity=100.0, speed=1.0,
        model=proud["model"]["name"], version="0.0.1", clips=1, frames=30, spread=0.0,
    )  # fmt: skip
    (styles_dir / "stale.json").write_text(json.dumps(stale.to_json()))
    listed = {s["name"]: s for s in client.get("/v1/styles").json()["translator"]}
    assert listed["stale"]["model_version"] == "0.0.1"
    body = assert_problem(transfer(client, style_name="stale"), 409, "conflict")
    assert "register it again" in body["detail"] and body["registered_with"].endswith("/0.0.1")
    (styles_dir / "broken.json").write_text("{not json")  # skipped, logged
    assert "broken" not in {s["name"] for s in client.get("/v1/styles").json()["translator"]}
    assert client.delete("/v1/styles/stale").status_code == 204
    (styles_dir / "broken.json").unlink()


def test_count_and_clips_are_limited(make_client, tmp_path):
    client = make_client(Settings(styles_dir=tmp_path, max_registered_styles=1, max_style_clips=2))
    clip = ("walk.bvh", FIXTURE.read_bytes())
    body = assert_problem(register(client, "three", clip, clip, clip), 413, "too-large")
    assert body["limit"] == 2 and body["limit_name"] == "max_style_clips"
    assert register(client, "one", clip).status_code == 201
    body = assert_problem(register(client, "two", clip), 409, "conflict")
    assert body["limit"] == 1 and body["limit_name"] == "max_registered_styles"
    assert client.delete("/v1/styles/one").status_code == 204
    assert register(client, "two", clip).status_code == 201


def test_two_apps_on_one_folder_see_each_others_styles_at_once(make_client, tmp_path):
    first = make_client(Settings(styles_dir=tmp_path))
    second = make_client(Settings(styles_dir=tmp_path))
    assert register(first, "shared", ("walk.bvh", FIXTURE.read_bytes())).status_code == 201
    assert "shared" in {s["name"] for s in second.get("/v1/styles").json()["translator"]}
    assert transfer(second, style_name="shared").status_code == 200
    assert_problem(register(second, "shared", ("walk.bvh", FIXTURE.read_bytes())), 409)
    assert second.delete("/v1/styles/shared").status_code == 204
    assert_problem(transfer(first, style_name="shared"), 404)


def test_a_folder_that_cannot_be_written_is_a_507(make_client, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    client = make_client(Settings(styles_dir=blocker / "styles"))
    body = assert_problem(register(client, "nowhere", ("walk.bvh", FIXTURE.read_bytes())), 507)
    assert "MOTION_STYLES_DIR" in body["detail"]
    assert client.get("/v1/styles").status_code == 200
    assert_problem(client.delete("/v1/styles/nowhere"), 404)


# --- a real server: restarted, and with two workers --------------------------------------


def test_a_style_registered_from_xias_old_clip_survives_a_restart_on_every_worker(tmp_path):
    old = data_path("xia", "old_13_000.bvh").read_bytes()
    walk = {"content": ("walk.bvh", FIXTURE.read_bytes(), "text/plain")}
    env = {"MOTION_STYLES_DIR": str(tmp_path / "styles"), "MOTION_LOG_LEVEL": "warning"}
    with ServerProcess(env=env, log_path=tmp_path / "first.log") as server:
        r = httpx.post(server.url + "/v1/styles", data={"name": "xia-old"},
                       files=clip_files(("old_13_000.bvh", old)), timeout=60)  # fmt: skip
        assert r.status_code == 201, r.text
        before = httpx.post(server.url + "/v1/transfer", files=walk,
                            data={"style_name": "xia-old"}, timeout=60)  # fmt: skip
        assert before.status_code == 200, before.text
        before = bvh.loads(before.text)
        assert np.abs(before.lrot - bvh.load(FIXTURE).lrot[: before.num_frames]).max() > 0.1

    env.update({"MOTION_WORKERS": "2", "MOTION_INTRA_OP_THREADS": "1"})
    with ServerProcess(env=env, log_path=tmp_path / "second.log") as server:
        server.wait_every_worker_ready()
        for _ in range(6):  # whichever worker answers
            r = httpx.post(server.url + "/v1/transfer", files=walk,
                           data={"style_name": "xia-old"}, timeout=60)  # fmt: skip
            assert r.status_code == 200, r.text
            after = bvh.loads(r.text)  # the same (onnxruntime on fewer threads: to rounding)
            assert after.num_frames == before.num_frames
            gap = K.global_positions(after) - K.global_positions(before)
            assert np.abs(gap).max() < 1e-4 * before.skeleton.height()
        assert httpx.delete(server.url + "/v1/styles/xia-old", timeout=10).status_code == 204
        for _ in range(6):
            r = httpx.post(server.url + "/v1/transfer", files=walk,
                           data={"style_name": "xia-old"}, timeout=60)  # fmt: skip
            assert r.status_code == 404, r.text

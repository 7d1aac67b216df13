"""``service.limits``: frames and audio seconds over the settings are 413 problems that name
the limit, through test-only routes shaped like the model endpoints."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import soundfile
from fastapi import FastAPI, File, Request, UploadFile

from motion import bvh
from service import limits
from service.config import Settings
from service.errors import PayloadTooLarge
from tests.api.helpers import assert_problem
from tests.robustness.corpus import TINY_BVH, keypoint_json, keypoint_zip

FIXTURE = "tests/data/cmu_02_01_walk_30fps.bvh"  # 60 frames


def wav(seconds: float, sr: int = 8000) -> bytes:
    buffer = io.BytesIO()
    t = np.arange(int(seconds * sr)) / sr
    soundfile.write(buffer, 0.5 * np.sin(2 * np.pi * 440 * t), sr, format="WAV")
    return buffer.getvalue()


def add_limit_routes(app: FastAPI) -> None:
    settings: Settings = app.state.settings

    @app.post("/_test/bvh")
    async def post_bvh(request: Request, content: UploadFile = File()):
        data = await content.read()
        motion = await request.app.state.runner.run(bvh.loads, data)
        limits.check_frames(motion, settings, what="content")
        return {"frames": motion.num_frames}

    @app.post("/_test/audio")
    async def post_audio(request: Request, audio: UploadFile = File()):
        data = await audio.read()
        samples, sr = await request.app.state.runner.run(limits.decode_audio, data, settings)
        return {"seconds": limits.check_audio_seconds(samples, settings, sr)}

    @app.post("/_test/keypoints")
    async def post_keypoints(request: Request, keypoints: UploadFile = File()):
        data = await keypoints.read()
        kp = await request.app.state.runner.run(limits.read_keypoints, data, settings)
        return {"frames": kp.num_frames}

    @app.get("/_test/result")
    async def get_result(frames: int):
        limits.check_frames(frames, settings, what="result")
        return {"frames": frames}


@pytest.fixture
def limited(make_client):
    settings = Settings(max_frames=59, max_audio_seconds=1.0, max_upload_bytes=100_000)
    return make_client(settings, setup=add_limit_routes)


def post_file(client, route: str, field: str, data: bytes):
    return client.post(route, files={field: ("upload", data)})


def test_clip_within_the_frame_limit_passes(make_client):
    client = make_client(Settings(max_frames=60), setup=add_limit_routes)
    with open(FIXTURE, "rb") as fh:
        response = post_file(client, "/_test/bvh", "content", fh.read())
    assert response.status_code == 200, response.text
    assert response.json() == {"frames": 60}


def test_clip_over_the_frame_limit_is_413_naming_it(limited):
    with open(FIXTURE, "rb") as fh:
        response = post_file(limited, "/_test/bvh", "content", fh.read())
    body = assert_problem(response, 413, "too-large")
    assert body["limit"] == 59
    assert body["limit_name"] == "max_frames"
    assert body["frames"] == 60
    assert "content" in body["detail"] and "max_frames" in body["detail"]


def test_result_frames_are_checked_too(limited):
    assert limited.get("/_test/result", params={"frames": 59}).status_code == 200
    body = assert_problem(limited.get("/_test/result", params={"frames": 60}), 413)
    assert body["limit_name"] == "max_frames" and "result" in body["detail"]


def test_malformed_bvh_is_400_with_its_line(limited):
    body = assert_problem(
        post_file(
            limited, "/_test/bvh", "content", TINY_BVH.replace("OFFSET 0 10 0", "OFFSET x").encode()
        ),  # fmt: skip
        400,
        "invalid-input",
    )
    assert body["line"] == 8


def test_audio_within_the_limit_passes(limited):
    response = post_file(limited, "/_test/audio", "audio", wav(0.5))
    assert response.status_code == 200, response.text
    assert response.json()["seconds"] == pytest.approx(0.5)


def test_audio_over_the_limit_is_413_naming_it(limited):
    body = assert_problem(post_file(limited, "/_test/audio", "audio", wav(3.0)), 413, "too-large")
    assert body["limit"] == 1.0
    assert body["limit_name"] == "max_audio_seconds"
    assert "max_audio_seconds" in body["detail"]


def test_undecodable_audio_is_400(limited):
    assert_problem(post_file(limited, "/_test/audio", "audio", b"RIFF junk"), 400, "invalid-input")


def test_keypoints_over_the_frame_limit_are_413(make_client):
    client = make_client(Settings(max_frames=5), setup=add_limit_routes)
    for data in (keypoint_json(6), keypoint_zip(6)):
        body = assert_problem(post_file(client, "/_test/keypoints", "keypoints", data), 413)
        assert body["limit"] == 5 and body["limit_name"] == "max_frames"
    ok = post_file(client, "/_test/keypoints", "keypoints", keypoint_json(5))
    assert ok.status_code == 200, ok.text


def test_keypoint_zip_unpacking_past_the_upload_limit_is_413(make_client):
    client = make_client(Settings(max_upload_bytes=50_000), setup=add_limit_routes)
    frames = json.loads(keypoint_json(2))
    frames[0]["padding"] = " " * 60_000
    from tests.robustness.corpus import make_zip

    bomb = make_zip({"000.json": json.dumps(frames[:1]).encode(), "001.json": b"[]"})
    assert len(bomb) < 50_000
    body = assert_problem(post_file(client, "/_test/keypoints", "keypoints", bomb), 413)
    assert body["limit_name"] == "max_upload_bytes"


def test_helpers_directly():
    settings = Settings(max_frames=10, max_audio_seconds=2.0)
    assert limits.check_frames(10, settings) == 10
    with pytest.raises(PayloadTooLarge) as info:
        limits.check_frames(11, settings, what="style")
    assert info.value.status_code == 413 and info.value.ext["limit_name"] == "max_frames"
    assert limits.check_audio_seconds(2.0, settings) == 2.0
    assert limits.check_audio_seconds(np.zeros(16000), settings, 8000) == 2.0
    with pytest.raises(PayloadTooLarge):
        limits.check_audio_seconds(np.zeros(16001), settings, 8000)
    with pytest.raises(ValueError):
        limits.check_audio_seconds(np.zeros(10), settings, 0)

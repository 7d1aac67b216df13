"""``POST /v1/stylize`` against the real app and the SHIPPED fast models (models/)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motion import bvh
from service.config import Settings
from service.engines.restyling import MAX_WARP, MIN_WARP
from tests.api.helpers import assert_problem
from tests.conftest import data_path


def shipped_fast_styles() -> list[str]:
    try:
        doc = json.loads((Settings().models_dir[0] / "manifest.json").read_text())
    except (OSError, ValueError):
        return []
    return sorted(
        name
        for model in doc.get("models", [])
        if model.get("family") == "fast"
        for name in model.get("extra", {}).get("styles", {})
    )


STYLES = shipped_fast_styles()
pytestmark = pytest.mark.skipif(not STYLES, reason="no fast models shipped in models/")


def post(client, data: bytes, style: str, name: str = "clip.bvh", query: str = "", **fields):
    """A stylize request; no time warp unless ``time_warp`` is given, so frames are kept."""
    return client.post(
        "/v1/stylize" + query,
        files={"content": (name, data, "text/plain")},
        data={"style_name": style, "time_warp": "false", **fields},
    )


def assert_same_rig(result_text: str, source: bytes) -> None:
    """The answer is a BVH on the input's skeleton: joint names, channel order, offsets,
    End Sites, frame rate and frame count."""
    a, b = bvh.loads(source), bvh.loads(result_text)
    assert b.skeleton.names == a.skeleton.names
    assert b.skeleton.channels == a.skeleton.channels
    np.testing.assert_allclose(b.skeleton.offsets, a.skeleton.offsets, atol=1e-4)
    assert b.num_frames == a.num_frames
    assert abs(b.fps - a.fps) < 1e-3
    assert np.all(np.isfinite(b.lrot)) and np.all(np.isfinite(b.lpos))


def test_styles_are_listed(shared_client):
    body = shared_client.get("/v1/styles").json()
    fast = {s["name"]: s for s in body["fast"]}
    assert sorted(fast) == STYLES
    assert all(s["clips"] > 0 for s in fast.values())


@pytest.mark.parametrize("style", STYLES)
def test_every_style_on_the_cmu_fixture(shared_client, walk, style):
    response = post(shared_client, walk, style, name="walk.bvh")
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "text/plain; charset=utf-8"
    assert response.headers["content-disposition"].startswith("attachment")
    assert_same_rig(response.text, walk)
    assert response.headers["x-frames"] == str(bvh.loads(walk).num_frames)
    for header in ("x-request-id", "x-model-version", "x-fps", "server-timing"):
        assert response.headers.get(header), header


def test_result_differs_from_input_and_keeps_the_path(shared_client, walk):
    source = bvh.loads(walk)
    out = bvh.loads(post(shared_client, walk, STYLES[0]).text)
    assert np.abs(out.lrot - source.lrot).max() > 1e-3  # something changed
    travel_in = source.lpos[-1, 0, [0, 2]] - source.lpos[0, 0, [0, 2]]
    travel_out = out.lpos[-1, 0, [0, 2]] - out.lpos[0, 0, [0, 2]]
    np.testing.assert_allclose(travel_out, travel_in, atol=0.1 * np.linalg.norm(travel_in) + 1)


def test_json_format_and_no_cleanup(shared_client, walk):
    response = post(shared_client, walk, STYLES[-1], query="?format=json", foot_cleanup="false")
    assert response.status_code == 200, response.text
    body = response.json()
    keys = {"bvh", "frames", "fps", "model", "timings_ms", "warnings", "rig", "source_format",
            "loop"}  # fmt: skip
    assert set(body) == keys
    assert body["source_format"] == "bvh"
    assert body["rig"]["method"] == "names" and 0 < body["rig"]["confidence"] <= 1
    assert "foot_cleanup" not in body["timings_ms"] and "network" in body["timings_ms"]
    assert body["frames"] == bvh.loads(walk).num_frames
    assert_same_rig(body["bvh"], walk)


def test_bandai_clip(shared_client):
    source = data_path("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh").read_bytes()
    response = post(shared_client, source, "angry" if "angry" in STYLES else STYLES[0])
    assert response.status_code == 200, response.text
    assert_same_rig(response.text, source)


def test_daz_43_joint_clip(shared_client):
    source = data_path("cmu-dance-43", "05_11_pirouette.bvh").read_bytes()
    response = post(shared_client, source, STYLES[len(STYLES) // 2])
    assert response.status_code == 200, response.text
    assert_same_rig(response.text, source)


def test_short_clip_is_padded_not_refused(shared_client, walk):
    motion = bvh.loads(walk).slice(0, 3)
    source = bvh.dumps(motion).encode()
    response = post(shared_client, source, STYLES[0])
    assert response.status_code == 200, response.text
    assert bvh.loads(response.text).num_frames == 3


def test_unknown_style_is_404(shared_client, walk):
    body = assert_problem(post(shared_client, walk, "no-such-style"), 404, "not-found")
    assert sorted(body["styles"]) == STYLES


def test_malformed_bvh_is_400_with_line(shared_client):
    text = b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n"
    body = assert_problem(post(shared_client, text, STYLES[0]), 400, "invalid-input")
    assert body["line"] == 4


def test_missing_fields_are_400(shared_client, walk):
    response = shared_client.post("/v1/stylize", data={"style_name": STYLES[0]})
    assert_problem(response, 400, "invalid-request")
    response = shared_client.post("/v1/stylize", files={"content": ("a.bvh", walk, "text/plain")})
    assert_problem(response, 400, "invalid-request")
    assert_problem(post(shared_client, walk, STYLES[0], query="?format=xml"), 400)


def test_wrong_media_type_is_415(shared_client):
    response = shared_client.post(
        "/v1/stylize",
        files={"content": ("a.png", b"\x89PNG\r\n\x1a\n", "image/png")},
        data={"style_name": STYLES[0]},
    )
    assert_problem(response, 415, "unsupported-media-type")


def test_unmappable_skeleton_is_422(shared_client):
    text = (
        b"HIERARCHY\nROOT Pelvis\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition"
        b" Zrotation Xrotation Yrotation\n JOINT Tail\n {\n  OFFSET 0 -10 0\n  CHANNELS 3"
        b" Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -5 0\n  }\n }\n}\n"
        b"MOTION\nFrames: 2\nFrame Time: 0.0333333\n0 0 0 0 0 0 0 0 0\n0 0 0 0 0 0 0 0 0\n"
    )
    body = assert_problem(post(shared_client, text, STYLES[0]), 422, "unusable-input")
    assert body["unmapped"]


def test_bad_mapping_is_400(shared_client, walk):
    response = post(shared_client, walk, STYLES[0], mapping="{not json")
    assert_problem(response, 400, "invalid-request")
    response = post(shared_client, walk, STYLES[0], mapping="[1, 2]")
    assert_problem(response, 400, "invalid-request")


def test_too_many_frames_is_413(make_client, walk):
    client = make_client(Settings(max_frames=10))
    body = assert_problem(post(client, walk, STYLES[0]), 413, "too-large")
    assert body["limit"] == 10


def fast_speeds() -> dict[str, float]:
    doc = json.loads((Settings().models_dir[0] / "manifest.json").read_text())
    entry = next(m for m in doc["models"] if m["family"] == "fast")
    return {name: info["speed"] for name, info in entry["extra"]["styles"].items()}


def test_a_named_style_plays_at_its_speed(shared_client, walk):
    """By default the result plays at the style's speed against the other styles on the same
    actions (the translator's, clamped to 0.5-2x): a sad walk is longer, an angry one
    shorter; the path is the same."""
    frames = bvh.loads(walk).num_frames
    speeds = fast_speeds()
    for style in ("sad", "angry"):
        factor = min(max(speeds[style], MIN_WARP), MAX_WARP)
        assert abs(np.log(factor)) > 0.2  # the case is real
        r = post(shared_client, walk, style, time_warp="true")
        assert r.status_code == 200, r.text
        assert r.headers["x-frames"] == str(round((frames - 1) / factor) + 1)
        still = bvh.loads(post(shared_client, walk, style).text)
        warped = bvh.loads(r.text)
        np.testing.assert_allclose(warped.lpos[-1, 0], still.lpos[-1, 0], atol=1e-3)


def test_the_other_names_of_a_style_give_the_same_result(shared_client, walk):
    """Bandai dataset 1's names (old, tired, masculinity) are the merged styles' other names."""
    for alias, style in (("old", "elderly"), ("tired", "exhausted"), ("masculinity", "masculine")):
        assert post(shared_client, walk, alias).text == post(shared_client, walk, style).text
    assert "old" not in {s["name"] for s in shared_client.get("/v1/styles").json()["fast"]}


def test_the_networks_see_mirrored_frames_as_far_as_they_reach(shared_client, walk):
    """Each end of a clip is mirrored over as many frames as the bundle says its networks
    see: fewer and its first and last frames would read zeros."""
    from motion import features as Fe
    from service.clips import Upload
    from service.metrics import StageTimer
    from service.requests import ContentClip, StylizeRequest

    for frames in (3, 40, 60):  # 40 frames padded to 64 would leave 12 at each end
        source = bvh.dumps(bvh.loads(walk).slice(0, frames)).encode()
        content = ContentClip(Upload("content", data=source, filename="walk.bvh"))
        request = StylizeRequest(content, STYLES[0])
        engine = shared_client.app.state.registry.engine_for("fast", request)
        reach = int(engine.entry.extra["receptive_field"])
        job = engine.prepare(request, StageTimer(engine.name))
        x, offset = engine.network_input(Fe.encode(job.content))
        assert offset >= reach, frames
        assert x.shape[2] - offset - job.content.num_frames >= reach, frames


def test_a_style_plays_at_its_own_strength(shared_client, walk, monkeypatch):
    """A style whose bundle entry names a strength (active, at 1.2: past the network's pose)
    is played that far from the content's pose, further than at 1; without one, at the
    bundle's (0.95): nearer the content."""
    from motion import kinematics as K
    from service.clips import Upload
    from service.requests import ContentClip, StylizeRequest

    content = ContentClip(Upload("content", data=walk, filename="walk.bvh"))
    request = StylizeRequest(content, "active")
    engine = shared_client.app.state.registry.engine_for("fast", request)
    own, default = engine.style_info["active"].get("strength"), engine.strength
    assert own is not None and own > 1.0 > default  # the case is real

    def distance_to_content(text: str) -> float:
        content, result = bvh.loads(walk), bvh.loads(text)
        gap = K.global_positions(result) - K.global_positions(content)
        return float(np.linalg.norm(gap, axis=-1).mean())

    at_own = distance_to_content(post(shared_client, walk, "active").text)
    monkeypatch.setitem(engine.style_info["active"], "strength", 1.0)
    at_one = distance_to_content(post(shared_client, walk, "active").text)
    monkeypatch.delitem(engine.style_info["active"], "strength")
    at_default = distance_to_content(post(shared_client, walk, "active").text)
    assert at_default < at_one < at_own

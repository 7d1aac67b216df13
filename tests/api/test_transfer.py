"""``POST /v1/transfer`` and the translator's ``GET /v1/styles``, against the real app and the
SHIPPED translator (``models/translator``). Its engine alone: test_translator_engine.py;
``/v1/style-code``: test_style_code.py; bad input: test_transfer_errors.py."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from motion import bvh, retarget
from motion import contacts as CT
from motion import features as Fe
from motion import kinematics as K
from service.config import Settings
from service.engines.restyling import MAX_WARP, MIN_WARP
from service.engines.translator import (
    SAME_STYLE_FAR,
    SAME_STYLE_NEAR,
)
from tests import rigs
from tests.api.translator_helpers import (
    ENTRY,
    STYLES,
    bandai,
    needs_model,
    transfer,
)
from tests.conftest import data_path


def assert_same_rig(result_text: str, source: bytes, frames: int | None = None):
    """A BVH on the source's skeleton (names, channels, offsets) and frame rate; the frame
    count ``frames`` when given. Returns the parsed result."""
    a, b = bvh.loads(source), bvh.loads(result_text)
    assert b.skeleton.names == a.skeleton.names
    assert b.skeleton.channels == a.skeleton.channels
    np.testing.assert_allclose(b.skeleton.offsets, a.skeleton.offsets, atol=1e-4)
    assert abs(b.fps - a.fps) < 1e-3
    assert np.all(np.isfinite(b.lrot)) and np.all(np.isfinite(b.lpos))
    if frames is not None:
        assert b.num_frames == frames
    return b


def assert_transfer_ok(response, source: bytes, frames: int | None = None):
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "text/plain; charset=utf-8"
    out = assert_same_rig(response.text, source, frames)
    assert response.headers["x-frames"] == str(out.num_frames)
    assert float(response.headers["x-fps"]) == pytest.approx(bvh.loads(source).fps, rel=1e-4)
    assert response.headers["x-model-version"] == f"{ENTRY['name']}/{ENTRY['version']}"
    return out


def expected_warp(content: bytes, style_velocity: float) -> float:
    """The paper's warp for a style clip: the ratio of velocity factors, clamped."""
    canon = retarget.to_canonical(bvh.loads(content))
    factor = style_velocity / Fe.velocity_factor(canon)
    return min(max(factor, MIN_WARP), MAX_WARP)


def warped_frames(frames: int, factor: float) -> int:
    return round((frames - 1) / factor) + 1


def speeds() -> dict[str, float]:
    return {name: info["speed"] for name, info in ENTRY["extra"]["styles"].items()}


def style_gap() -> float:
    """The smallest gap between learned codes (the engine's; named codes lie further out)."""
    with np.load(Settings().models_dir[0] / ENTRY["extra"]["styles_file"]) as table:
        codes = table["codes"]
    gaps = np.linalg.norm(codes[:, None] - codes[None], axis=-1)
    return float(gaps[~np.eye(len(codes), dtype=bool)].min())


def nearest_style(client, clip: bytes) -> dict:
    """The named style nearest ``clip``'s own code, and its distance (/v1/style-code)."""
    response = client.post("/v1/style-code", files={"style": ("c.bvh", clip, "text/plain")})
    assert response.status_code == 200, response.text
    return response.json()["nearest"][0]


def own_speed(client, clip: bytes) -> float:
    """The speed of the named style ``clip`` is in (1 in none), by the engine's rule."""
    nearest = nearest_style(client, clip)
    near, far = SAME_STYLE_NEAR * style_gap(), SAME_STYLE_FAR * style_gap()
    weight = min(max((far - nearest["distance"]) / (far - near), 0.0), 1.0)
    return speeds()[nearest["style"]] ** weight


@needs_model
def test_styles_are_listed(shared_client):
    body = shared_client.get("/v1/styles").json()
    listed = {s["name"]: s for s in body["translator"]}
    assert sorted(listed) == STYLES
    for name, info in listed.items():
        assert info["clips"] == ENTRY["extra"]["styles"][name]["clips"] > 0
        assert info["speed"] == ENTRY["extra"]["styles"][name]["speed"] > 0
        assert info["model"] == ENTRY["name"]


@needs_model
def test_shipped_style_names_match_whatever_their_case(shared_client, walk):
    """A user who types "Elderly" gets the shipped ``elderly``: the same answer as the
    model's own spelling, on both families and in a mix, where both spellings add up."""
    style = STYLES[0]
    asked = style.upper()
    assert asked != style
    same = transfer(shared_client, walk, style_name=style)
    upper = transfer(shared_client, walk, style_name=asked)
    assert same.status_code == upper.status_code == 200 and upper.text == same.text
    mix = transfer(shared_client, walk, style_mix=json.dumps({asked: 1, style: 1}))
    assert mix.status_code == 200 and mix.text == same.text
    codes = [
        shared_client.post("/v1/style-code", data={"style_name": name}).json()["code"]
        for name in (style, f"bandai:{asked.capitalize()}")
    ]
    assert codes[0] == codes[1]
    content = {"content": ("walk.bvh", walk, "text/plain")}
    fast = [
        shared_client.post("/v1/stylize", files=content, data={"style_name": name})
        for name in ("proud", "Proud")
    ]
    assert fast[0].status_code == fast[1].status_code == 200 and fast[0].text == fast[1].text


@needs_model
def test_bandai_content_with_a_bandai_style_clip(shared_client):
    content = bandai("dataset-1_walk-right_masculinity_001")
    style = bandai("dataset-1_run_tired_001")
    response = transfer(shared_client, content, files={"style": ("s.bvh", style, "text/plain")})
    out = assert_transfer_ok(response, content)
    style_velocity = Fe.velocity_factor(retarget.to_canonical(bvh.loads(style)))
    factor = expected_warp(content, style_velocity)
    assert out.num_frames == round((bvh.loads(content).num_frames - 1) / factor) + 1
    assert "style_parse" in response.headers["server-timing"]


@needs_model
def test_cmu_fixture_with_a_style_name_is_warped_and_keeps_unmapped_joints(shared_client, walk):
    source = bvh.loads(walk)
    # a slow style: a fast one's warp may be capped at real mocap's speeds (active on this
    # walk would swing its toes at 8.8 body heights a second at 2x)
    name = "elderly" if "elderly" in STYLES else STYLES[0]
    out = assert_transfer_ok(transfer(shared_client, walk, style_name=name), walk)
    factor = speeds()[name] / own_speed(shared_client, walk)  # a named style's relative speed
    factor = min(max(factor, MIN_WARP), MAX_WARP)
    assert out.num_frames == warped_frames(source.num_frames, factor)
    # joints with no canonical counterpart follow the warped original
    rig = retarget.make_rig(source.skeleton, source)
    unmapped = [source.skeleton.index(n) for n in rig.unmapped]
    assert unmapped
    warped = Fe.time_warp(source, factor, out.num_frames)
    dots = np.abs(np.sum(out.lrot[:, unmapped] * warped.lrot[:, unmapped], axis=-1))
    assert dots.min() > 1 - 1e-5


@needs_model
def test_named_styles_warp_by_speed_whatever_the_content(shared_client, walk):
    """A slow style slows a run and a bow alike, relative to the style each is in, and a mix
    warps by the weighted geometric mean of its speeds (the mean velocity factor of a
    style's clips would slow every run and speed up every bow: it mixes contents)."""
    speed = speeds()
    slow, fast = min(speed, key=speed.get), max(speed, key=speed.get)
    assert speed[slow] < 0.9 and speed[fast] > 1.1
    for clip in ("dataset-1_run_normal_001", "dataset-1_bow_normal_001"):
        content = bandai(clip)
        frames, own = bvh.loads(content).num_frames, own_speed(shared_client, content)
        for name in (slow, fast):
            response = transfer(shared_client, content, "?format=json", style_name=name)
            assert response.status_code == 200, response.text
            body = response.json()
            factor = min(max(speed[name] / own, MIN_WARP), MAX_WARP)
            capped = [w for w in body["warnings"] if "lowered" in w]  # past real mocap's speeds
            if capped:
                assert factor > 1.0 and body["frames"] > warped_frames(frames, factor)
                lowered = float(capped[0].split(" lowered to ")[1].split(":")[0])
                assert abs(body["frames"] - warped_frames(frames, lowered)) <= 1, (clip, name)
            else:
                assert body["frames"] == warped_frames(frames, factor), (clip, name)
    mix = {slow: 0.25, fast: 0.75}
    out = transfer(shared_client, walk, style_mix=json.dumps(mix), strength="0.5")
    factor = (speed[slow] ** 0.25 * speed[fast] ** 0.75 / own_speed(shared_client, walk)) ** 0.5
    assert_transfer_ok(out, walk, frames=warped_frames(bvh.loads(walk).num_frames, factor))


@needs_model
def test_a_clip_restyled_to_the_named_style_it_is_in_keeps_its_timing(shared_client):
    """A not-confident walk (the slowest style) restyled "not-confident" is not slowed
    further, nor a childish walk (a fast style) sped up; to another style it warps by the ratio of the
    two styles' speeds."""
    speed = speeds()
    for clip, style in [
        ("dataset-1_walk_not-confident_002", "not-confident"),
        ("dataset-1_walk_childish_002", "childish"),
    ]:
        content = bandai(clip)
        nearest = nearest_style(shared_client, content)
        assert nearest["style"] == style and nearest["distance"] < SAME_STYLE_NEAR * style_gap()
        assert abs(math.log(speed[style])) > 0.2  # alone, its speed would warp it visibly
        frames = bvh.loads(content).num_frames
        out = assert_transfer_ok(transfer(shared_client, content, style_name=style), content)
        assert out.num_frames == frames, clip
        other = "normal"
        out = assert_transfer_ok(transfer(shared_client, content, style_name=other), content)
        factor = min(max(speed[other] / speed[style], MIN_WARP), MAX_WARP)
        assert out.num_frames == warped_frames(frames, factor) != frames, clip


def _lowest_foot_level(motion) -> float:
    """The lowest planted height of a clip's feet and toes, in body heights."""
    names = motion.skeleton.names
    feet = [j for j, n in enumerate(names) if "foot" in n.lower() or "toe" in n.lower()]
    gpos = K.global_positions(motion)
    height = float(np.median(np.ptp(gpos[..., 1], axis=1)))
    return float(CT.ground_heights(gpos, feet).min()) / height


@needs_model
@pytest.mark.parametrize(
    ("clip", "style", "tolerance"),
    [
        (None, "proud", 0.03),  # the repository's CMU walk: 5.8% of its height under, before
        (None, "elderly", 0.03),  # 4.3% before
        (("xia", "neutral_16_000.bvh"), "happy", 0.1),  # 22.7% before
    ],
)
def test_a_transfer_stands_on_the_contents_floor(shared_client, walk, clip, style, tolerance):
    """The decoder's legs may be straighter than the content's under the content's hips
    height; the hips move so that the planted feet do not sink into the content's floor."""
    content = walk if clip is None else data_path(*clip).read_bytes()
    out = assert_transfer_ok(transfer(shared_client, content, style_name=style), content)
    sunk = _lowest_foot_level(bvh.loads(content)) - _lowest_foot_level(out)
    assert sunk < tolerance, f"feet {sunk:.1%} of the body's height under the floor"


@needs_model
def test_without_time_warp_the_frame_count_is_the_contents(shared_client, walk):
    response = transfer(shared_client, walk, style_name=STYLES[0], time_warp="false")
    assert_transfer_ok(response, walk, frames=bvh.loads(walk).num_frames)


@needs_model
def test_keypoints_of_a_real_video(shared_client, walk, treadmill_zip):
    response = transfer(
        shared_client,
        walk,
        query="?format=json",
        files={"keypoints": ("treadmill.zip", treadmill_zip, "application/zip")},
        keypoints_fps="23.976",
    )
    assert response.status_code == 200, response.text
    body = response.json()
    assert_same_rig(body["bvh"], walk, frames=bvh.loads(walk).num_frames)  # no warp
    assert any("no time warp" in w for w in body["warnings"])


@needs_model
def test_style_mix_and_json_format(shared_client, walk):
    mix = json.dumps({STYLES[0]: 0.7, STYLES[-1]: 0.3})
    response = transfer(shared_client, walk, query="?format=json", style_mix=mix)
    assert response.status_code == 200, response.text
    body = response.json()
    keys = {"bvh", "frames", "fps", "model", "timings_ms", "warnings", "rig", "source_format",
            "loop"}  # fmt: skip
    assert set(body) == keys
    assert body["source_format"] == "bvh"
    assert body["rig"]["method"] == "names" and body["rig"]["confidence"] == 1.0
    assert body["rig"]["mapping"]["UpperLeg_L"] == "LeftUpLeg"
    assert body["model"] == {"name": ENTRY["name"], "version": ENTRY["version"]}
    for stage in ("encode", "decode", "foot_cleanup", "retarget_back", "write"):
        assert stage in body["timings_ms"], stage
    out = assert_same_rig(body["bvh"], walk)
    assert out.num_frames == body["frames"] == int(response.headers["x-frames"])


@needs_model
def test_strength_zero_gives_the_clip_back(shared_client, walk):
    """At strength 0 every joint keeps the content's pose: any two styles give the same clip,
    and that clip is the one sent, frame for frame, the foot clean-up's pins included (they
    moved a knee of this walk by 5 % of its height). A leading bind pose and a cycle come
    back as sent too."""
    a = transfer(shared_client, walk, style_name=STYLES[0], strength="0", time_warp="false")
    b = transfer(shared_client, walk, style_name=STYLES[-1], strength="0")
    c = transfer(shared_client, walk, style_name=STYLES[-1], time_warp="false")
    for r in (a, b, c):
        assert r.status_code == 200, r.text
    assert a.text == b.text
    assert a.text != c.text
    sent = bvh.loads(walk)
    for clip, loop in (
        (sent, False),
        (rigs.bind_pose_first(sent), False),
        (rigs.walk_cycle(), True),
    ):
        r = transfer(shared_client, bvh.dumps(clip).encode(), style_name=STYLES[0],
                     strength="0", query="?format=json")  # fmt: skip
        assert r.status_code == 200, r.text
        assert r.json()["loop"] is loop
        r = transfer(shared_client, bvh.dumps(clip).encode(), style_name=STYLES[0], strength="0")
        back = bvh.loads(r.text)
        assert back.num_frames == clip.num_frames
        error = np.abs(K.global_positions(back) - K.global_positions(clip)).max()
        assert error < 1e-4 * clip.skeleton.height(), (loop, error)


@needs_model
def test_a_z_up_file_is_styled_as_its_y_up_twin(shared_client, walk):
    """A 3ds Max style Z-up export gets the Y-up file's result, in its own Z-up world."""
    z_up = bvh.dumps(rigs.z_up(bvh.loads(walk))).encode()
    a = transfer(shared_client, walk, style_name=STYLES[0])
    b = transfer(shared_client, z_up, style_name=STYLES[0])
    out_y = K.global_positions(assert_transfer_ok(a, walk))
    out_z = K.global_positions(assert_transfer_ok(b, z_up))
    turned = np.stack([out_z[..., 0], out_z[..., 2], -out_z[..., 1]], axis=-1)  # back to Y-up
    assert np.abs(turned - out_y).max() < 0.05  # cm: BVH text rounding


@needs_model
def test_another_name_of_a_style_is_that_style(shared_client, walk):
    """Bandai's dataset 1 calls elderly "old": both names give one result, and the style
    list gives the one name with the other."""
    old = transfer(shared_client, walk, style_name="old", time_warp="false")
    elderly = transfer(shared_client, walk, style_name="elderly", time_warp="false")
    assert old.status_code == elderly.status_code == 200
    assert old.text == elderly.text
    styles = shared_client.get("/v1/styles").json()["translator"]
    entry = next(s for s in styles if s["name"] == "elderly")
    assert entry["also_named"] == ["old"]
    assert "old" not in {s["name"] for s in styles}


@needs_model
def test_short_clip_is_padded_not_refused(shared_client, walk):
    source = bvh.dumps(bvh.loads(walk).slice(0, 3)).encode()
    response = transfer(shared_client, source, style_name=STYLES[0], time_warp="false")
    assert_transfer_ok(response, source, frames=3)

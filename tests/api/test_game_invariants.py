"""The invariants game animation lives by, through the HTTP API with the shipped models:
a looping clip comes back looping in every style of both families (time warp on or off),
a capture's leading T-pose frame comes back unchanged, ``root_motion=in_place`` holds the
hips over one spot (and a cycle in place still loops), and a field the endpoint does not
read is a 400 that names it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motion import bvh, retarget
from motion import kinematics as K
from tests import rigs
from tests.api.helpers import assert_problem
from tests.conftest import data_path

ENDPOINTS = {"translator": "/v1/transfer", "fast": "/v1/stylize"}


def restyle(client, family: str, clip, style: str, **fields) -> dict:
    """The JSON answer (``format=json``) of ``clip`` in ``style``; its result parsed."""
    response = client.post(
        ENDPOINTS[family],
        params={"format": "json"},
        files={"content": ("clip.bvh", bvh.dumps(clip))},
        data={"style_name": style, **{k: str(v).lower() for k, v in fields.items()}},
    )
    assert response.status_code == 200, response.text
    body = response.json()
    body["motion"] = bvh.loads(body["bvh"])
    return body


def about_the_hips(motion) -> np.ndarray:
    """Joint positions with the hips' horizontal travel taken out (root travel aside)."""
    gpos = K.global_positions(motion)
    hips = retarget.make_rig(motion.skeleton, motion).mapping["Hips"]
    return gpos - gpos[:, hips : hips + 1] * np.array([1.0, 0.0, 1.0])


def loop_jump_in_steps(motion) -> float:
    """The jump from the last pose to the first in median frame-to-frame steps."""
    local = about_the_hips(motion)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    return float(np.linalg.norm(local[-1] - local[0], axis=-1).mean() / np.median(steps))


@pytest.fixture(scope="module")
def styles(shared_client) -> dict[str, list[str]]:
    listing = shared_client.get("/v1/styles").json()
    return {f: sorted(s["name"] for s in listing[f] if not s.get("registered")) for f in ENDPOINTS}


@pytest.fixture(scope="module")
def mixamo_walk():
    """A closed walk cycle on a Mixamo-named rig: its last frame repeats its first."""
    return rigs.walk_cycle(rig_names=rigs.CMU_TO_MIXAMO)


def test_a_walk_cycle_stays_a_cycle_in_every_style_of_both_families(
    shared_client, styles, mixamo_walk
):
    assert loop_jump_in_steps(mixamo_walk) < 1e-6
    worst = {}
    for family, names in styles.items():
        for style in names:
            body = restyle(shared_client, family, mixamo_walk, style)
            assert body["loop"] is True, (family, style)
            worst[(family, style)] = loop_jump_in_steps(body["motion"])
    assert max(worst.values()) <= 1.5, sorted(worst.items(), key=lambda kv: -kv[1])[:3]


def test_a_held_back_authored_cycle_stays_a_cycle_in_every_style(shared_client, styles):
    """Bandai's dash (an open cycle, its travel on joint_Root): no Bandai cycle chose the
    loop tolerances (``python -m training.game_invariants`` measures all four)."""
    dash = bvh.load(data_path("bandai", "dataset-1", "dataset-1_dash_normal_001.bvh"))
    worst = {}
    for family, names in styles.items():
        for style in names:
            body = restyle(shared_client, family, dash, style)
            assert body["loop"] is True, (family, style)
            worst[(family, style)] = loop_jump_in_steps(body["motion"])
    assert max(worst.values()) <= 1.5, sorted(worst.items(), key=lambda kv: -kv[1])[:3]


@pytest.mark.parametrize("family", ENDPOINTS)
def test_a_cycle_loops_without_the_time_warp_and_keeps_its_frames(
    shared_client, family, mixamo_walk
):
    body = restyle(shared_client, family, mixamo_walk, "active", time_warp=False)
    assert body["loop"] is True and body["frames"] == mixamo_walk.num_frames
    assert loop_jump_in_steps(body["motion"]) <= 1.5


def test_loop_false_turns_detection_off_and_loop_true_takes_any_clip_as_one(
    shared_client, mixamo_walk
):
    assert restyle(shared_client, "fast", mixamo_walk, "happy", loop="false")["loop"] is False
    walk = rigs.load_fixture().slice(0, 90)  # a stretch of a walk: its ends do not meet
    assert restyle(shared_client, "fast", walk, "happy")["loop"] is False
    forced = restyle(shared_client, "fast", walk, "happy", loop="true", time_warp=False)
    assert forced["loop"] is True
    assert loop_jump_in_steps(forced["motion"]) <= 1.5


@pytest.fixture(scope="module")
def cmu_take():
    """A CMU take as cgspeed exported it, T-pose first, cut to its first 2 s."""
    return bvh.load(data_path("cmu-31", "02_01.bvh")).slice(0, 241)


def test_a_t_pose_first_frame_comes_back_unchanged_in_every_style(shared_client, styles, cmu_take):
    height = retarget.make_rig(cmu_take.skeleton, cmu_take).height
    sent = K.global_positions(cmu_take.slice(0, 1))[0]
    worst = {}
    for family, names in styles.items():
        for style in names:
            body = restyle(shared_client, family, cmu_take, style)
            assert any("reference" in w for w in body["warnings"]), body["warnings"]
            back = K.global_positions(body["motion"].slice(0, 1))[0]
            worst[(family, style)] = float(np.linalg.norm(back - sent, axis=-1).max() / height)
            second = K.global_positions(body["motion"].slice(1, 2))[0]
            assert np.linalg.norm(second - sent, axis=-1).max() > 0.05 * height  # motion follows
    assert max(worst.values()) <= 0.02, sorted(worst.items(), key=lambda kv: -kv[1])[:3]


@pytest.mark.parametrize("family", ENDPOINTS)
def test_in_place_holds_the_hips_over_one_spot_and_keeps_the_bob(shared_client, family):
    walk = rigs.load_fixture().slice(0, 120)
    rig = retarget.make_rig(walk.skeleton, walk)
    kept = restyle(shared_client, family, walk, "proud", time_warp=False)["motion"]
    still = restyle(shared_client, family, walk, "proud", time_warp=False, root_motion="in_place")
    hips = rig.mapping["Hips"]
    travel = np.ptp(K.global_positions(still["motion"])[:, hips, [0, 2]], axis=0).max()
    assert travel < 0.02 * rig.height
    assert np.ptp(K.global_positions(kept)[:, hips, [0, 2]], axis=0).max() > 0.5 * rig.height
    bob = K.global_positions(still["motion"])[:, hips, 1]
    assert np.allclose(bob, K.global_positions(kept)[:, hips, 1], atol=1e-6 * rig.height)
    assert np.ptp(bob) > 0.005 * rig.height


def test_a_cycle_in_place_still_loops(shared_client, mixamo_walk):
    body = restyle(shared_client, "translator", mixamo_walk, "elderly", root_motion="in_place")
    assert body["loop"] is True
    motion = body["motion"]
    hips = retarget.make_rig(motion.skeleton, motion).mapping["Hips"]
    gpos = K.global_positions(motion)
    steps = np.linalg.norm(np.diff(gpos, axis=0), axis=-1).mean(axis=-1)
    assert np.linalg.norm(gpos[-1] - gpos[0], axis=-1).mean() <= 1.5 * np.median(steps)
    height = retarget.make_rig(motion.skeleton, motion).height
    assert np.ptp(gpos[:, hips, [0, 2]], axis=0).max() < 0.02 * height


@pytest.mark.parametrize(
    ("path", "fields"),
    [
        ("/v1/transfer", {"style_name": "happy", "root_motoin": "in_place"}),
        ("/v1/stylize", {"style_name": "happy", "looping": "true"}),
    ],
)
def test_an_unknown_form_field_is_a_400_that_names_it(shared_client, path, fields):
    clip = bvh.dumps(rigs.load_fixture().slice(0, 40))
    response = shared_client.post(path, files={"content": ("c.bvh", clip)}, data=fields)
    body = assert_problem(response, 400, "invalid-request")
    (unknown,) = set(fields) - {"style_name"}
    assert body["unknown"] == [unknown] and unknown in body["detail"]
    assert "root_motion" in body["known"]


def test_a_query_parameter_sent_as_a_form_field_is_a_400_that_says_where_it_goes(shared_client):
    clip = bvh.dumps(rigs.load_fixture().slice(0, 40))
    response = shared_client.post(
        "/v1/stylize",
        files={"content": ("c.bvh", clip)},
        data={"style_name": "happy", "format": "json"},
    )
    body = assert_problem(response, 400, "invalid-request")
    assert body["misplaced"] == ["format"] and body["unknown"] == []
    assert "?format=" in body["detail"] and "unknown field" not in body["detail"]


def test_an_unknown_query_parameter_is_a_400_and_bad_values_are_too(shared_client):
    clip = bvh.dumps(rigs.load_fixture().slice(0, 40))
    send = {"files": {"content": ("c.bvh", clip)}, "data": {"style_name": "happy"}}
    response = shared_client.post("/v1/stylize", params={"fromat": "json"}, **send)
    assert assert_problem(response, 400)["unknown"] == ["fromat"]
    for field, value in (("root_motion", "in-place"), ("loop", "maybe")):
        response = shared_client.post(
            "/v1/stylize", files=send["files"], data={"style_name": "happy", field: value}
        )
        assert field in json.dumps(assert_problem(response, 400))

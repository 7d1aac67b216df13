"""``POST /v1/transfer`` with bad input, against the real app and the SHIPPED translator:
each is its problem document (400, 404, 413, 415, 422), never a 500."""

from __future__ import annotations

import json

import pytest

from service.config import Settings
from tests.api.helpers import assert_problem
from tests.api.translator_helpers import (
    STYLES,
    UNMAPPABLE,
    needs_model,
    transfer,
)


@needs_model
def test_no_or_several_style_inputs_are_400(shared_client, walk):
    body = assert_problem(transfer(shared_client, walk), 400, "invalid-request")
    assert body["fields"] == []
    body = assert_problem(
        transfer(
            shared_client,
            walk,
            files={"style": ("s.bvh", walk, "text/plain")},
            style_name=STYLES[0],
        ),
        400,
        "invalid-request",
    )
    assert body["fields"] == ["style", "style_name"]
    assert "style_name" in body["detail"]
    assert_problem(shared_client.post("/v1/style-code", data={}), 400, "invalid-request")


@needs_model
def test_unknown_style_name_is_404(shared_client, walk):
    body = assert_problem(transfer(shared_client, walk, style_name="no-such-style"), 404)
    assert body["styles"] == STYLES
    mix = json.dumps({STYLES[0]: 1, "no-such-style": 1})
    assert_problem(transfer(shared_client, walk, style_mix=mix), 404, "not-found")
    response = shared_client.post("/v1/style-code", data={"style_name": "no-such-style"})
    assert_problem(response, 404, "not-found")


@needs_model
@pytest.mark.parametrize("mix", ["{not json", "[1, 2]", '{"happy": -1}', "{}", '{"a": "b"}'])
def test_bad_style_mix_is_400(shared_client, walk, mix):
    body = assert_problem(transfer(shared_client, walk, style_mix=mix), 400, "invalid-request")
    assert body["field"] == "style_mix"


@needs_model
@pytest.mark.parametrize("strength", ["2", "-0.5", "nan", "strong"])
def test_strength_out_of_range_is_400(shared_client, walk, strength):
    response = transfer(shared_client, walk, style_name=STYLES[0], strength=strength)
    assert_problem(response, 400, "invalid-request")


@needs_model
def test_non_bvh_content_is_400_with_line(shared_client):
    text = b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n"
    body = assert_problem(transfer(shared_client, text, style_name=STYLES[0]), 400)
    assert body["line"] == 4


@needs_model
def test_unmappable_skeleton_is_422(shared_client, walk):
    body = assert_problem(
        transfer(shared_client, UNMAPPABLE, style_name=STYLES[0]), 422, "unusable-input"
    )
    assert body["unmapped"]
    files = {"style": ("s.bvh", UNMAPPABLE, "text/plain")}
    body = assert_problem(transfer(shared_client, walk, files=files), 422, "unusable-input")
    assert body["unmapped"]


@needs_model
def test_wrong_media_types_are_415(shared_client, walk):
    files = {"keypoints": ("k.png", b"\x89PNG\r\n\x1a\n", "image/png")}
    assert_problem(transfer(shared_client, walk, files=files), 415, "unsupported-media-type")
    files = {"style": ("s.png", b"\x89PNG\r\n\x1a\n", "image/png")}
    assert_problem(transfer(shared_client, walk, files=files), 415, "unsupported-media-type")


@needs_model
def test_bad_keypoints_and_mappings_are_400(shared_client, walk):
    files = {"keypoints": ("k.json", b"{not json", "application/json")}
    assert_problem(transfer(shared_client, walk, files=files), 400)
    files = {"style": ("s.bvh", walk, "text/plain")}
    body = assert_problem(
        transfer(shared_client, walk, files=files, style_mapping="[1]"), 400, "invalid-request"
    )
    assert body["field"] == "style_mapping"
    response = transfer(shared_client, walk, style_name=STYLES[0], mapping="{nope")
    assert_problem(response, 400, "invalid-request")


@needs_model
def test_too_many_frames_is_413(make_client, walk):
    client = make_client(Settings(max_frames=10))
    body = assert_problem(transfer(client, walk, style_name=STYLES[0]), 413, "too-large")
    assert body["limit"] == 10

"""``POST /v1/style-code`` against the real app and the SHIPPED translator: a name's code, a
video's, codes bounded outside the learned styles, never-seen takes near their style."""

from __future__ import annotations

import tarfile
from pathlib import Path

import numpy as np

from service.engines.translator import (
    CODE_NORM_LIMIT,
)
from tests.api.translator_helpers import (
    ENTRY,
    STYLES,
    needs_model,
    video_zip,
)
from tests.conftest import data_path


@needs_model
def test_style_code_of_a_name_is_its_table_code(shared_client):
    name = STYLES[1]
    response = shared_client.post("/v1/style-code", data={"style_name": name})
    assert response.status_code == 200, response.text
    body = response.json()
    assert len(body["code"]) == ENTRY["extra"]["style_dim"]
    np.testing.assert_allclose(body["code"], ENTRY["extra"]["styles"][name]["code"], atol=1e-5)
    assert body["nearest"][0] == {"style": name, "distance": 0.0}
    distances = [n["distance"] for n in body["nearest"]]
    assert len(distances) == 5 and distances == sorted(distances)


def keypoints_code(client, zipped: bytes) -> dict:
    files = {"keypoints": ("k.zip", zipped, "application/octet-stream")}
    response = client.post("/v1/style-code", files=files, data={"keypoints_fps": "23.976"})
    assert response.status_code == 200, response.text
    body = response.json()
    assert len(body["code"]) == ENTRY["extra"]["style_dim"] and body["velocity_factor"] is None
    assert {n["style"] for n in body["nearest"]} <= set(STYLES)
    return body


@needs_model
def test_style_code_of_a_walking_video_is_among_the_learned_styles(shared_client, treadmill_zip):
    """The detector's hips, neck and head moved to the canonical joint centres, a real
    video's walk codes like the motion the encoder learned from (at 2D points it codes
    3-4x beyond every named style)."""
    body = keypoints_code(shared_client, treadmill_zip)
    table = np.asarray([s["code"] for s in ENTRY["extra"]["styles"].values()])
    assert np.linalg.norm(body["code"]) <= np.linalg.norm(table, axis=1).max()
    assert not any("outside the learned styles" in w for w in body["warnings"])


@needs_model
def test_style_code_far_outside_the_learned_styles_is_bounded(shared_client):
    body = keypoints_code(shared_client, video_zip(95))  # someone collapsing on a treadmill
    table = np.asarray([s["code"] for s in ENTRY["extra"]["styles"].values()])
    limit = CODE_NORM_LIMIT * np.linalg.norm(table, axis=1).max()
    assert np.linalg.norm(body["code"]) <= limit * (1 + 1e-4)
    assert any("outside the learned styles" in w for w in body["warnings"])


@needs_model
def test_codes_within_the_learned_styles_are_not_bounded(shared_client, walk):
    r = shared_client.post("/v1/style-code", files={"style": ("w.bvh", walk, "text/plain")})
    assert r.status_code == 200, r.text
    assert not any("outside the learned styles" in w for w in r.json()["warnings"])


def held_out_dataset2_takes() -> dict[str, bytes]:
    """Bandai dataset-2 takes the shipped translator never trained on (its validation rule:
    not as content, target or style clip), as BVH text by take name."""
    from training.bandai_library import held_out_take

    archive = data_path("bandai", "dataset-2", "dataset-2-subset.tar.xz")
    takes = {}
    with tarfile.open(archive) as tar:
        for member in tar.getmembers():
            name = Path(member.name).stem
            if member.name.endswith(".bvh") and held_out_take(name):
                takes[name] = tar.extractfile(member).read()
    return takes


@needs_model
def test_held_out_clips_are_near_their_style(shared_client):
    """A clip's style code lies near its style's: the true style is among the three nearest
    for most never-seen takes (chance: 3 in 16)."""
    takes = held_out_dataset2_takes()
    assert len(takes) >= 20
    hits = 0
    for take, text in takes.items():
        files = {"style": ("s.bvh", text, "text/plain")}
        body = shared_client.post("/v1/style-code", files=files).json()
        assert len(body["code"]) == ENTRY["extra"]["style_dim"]
        hits += take.split("_")[2] in [n["style"] for n in body["nearest"][:3]]
    assert hits >= 0.6 * len(takes), f"{hits} of {len(takes)} held-out clips near their style"


@needs_model
def test_a_style_clip_under_half_a_second_is_coded_with_a_warning(shared_client, walk):
    """A clip of a few frames codes (one pose holds some style), and the answer says that
    such clips carry less of it; two seconds of walk do not get the warning."""
    from motion import bvh
    from service.engines.translator import SHORT_STYLE_SECONDS

    whole = bvh.loads(walk)
    short = bvh.dumps(whole.slice(0, 5))
    for clip, warned in ((walk, False), (short, True)):
        r = shared_client.post("/v1/style-code", files={"style": ("w.bvh", clip, "text/plain")})
        assert r.status_code == 200, r.text
        said = [w for w in r.json()["warnings"] if f"under {SHORT_STYLE_SECONDS:g} s" in w]
        assert bool(said) == warned, r.json()["warnings"]
    assert "lasts 0.17 s" in said[0]  # 5 frames at 30 fps


@needs_model
def test_a_file_answer_carries_its_warnings_in_a_header(shared_client, walk):
    """A BVH answer has no body to hold warnings, so ``X-Warnings`` carries them as a JSON
    array: the short style clip's warning reaches a transfer answered as BVH, the same
    list as the JSON answer's, and the style code's header repeats its body's."""
    import json

    from motion import bvh

    short = bvh.dumps(bvh.loads(walk).slice(0, 5))
    files = {"content": ("c.bvh", walk, "text/plain"), "style": ("s.bvh", short, "text/plain")}
    as_file = shared_client.post("/v1/transfer", files=files)
    assert as_file.status_code == 200, as_file.text
    assert as_file.headers["content-type"].startswith("text/plain")
    in_header = json.loads(as_file.headers["x-warnings"])
    assert any("lasts 0.17 s" in w for w in in_header), in_header
    as_json = shared_client.post("/v1/transfer?format=json", files=files)
    assert json.loads(as_json.headers["x-warnings"]) == as_json.json()["warnings"] == in_header
    code = shared_client.post("/v1/style-code", files={"style": ("s.bvh", short, "text/plain")})
    assert json.loads(code.headers["x-warnings"]) == code.json()["warnings"]
    clean = shared_client.post("/v1/style-code", files={"style": ("w.bvh", walk, "text/plain")})
    assert clean.json()["warnings"] == [] and "x-warnings" not in clean.headers

"""Rigs of the corpus (tests/rigs.py) through every endpoint of the real app with the shipped
models, with no mapping: meaningless names, helpers, Z-up and scaled, Reallusion and Maya
_JNT conventions. Each answer keeps the rig's joint names, channels, frame count and rate;
a rig whose sides nothing tells apart gets a 422 that says how to pass a ``mapping``."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from motion import audio_decode, bvh
from service.config import Settings
from service.manifest import load_manifest
from tests import rigs
from tests.api.helpers import assert_problem
from tests.unit.test_rig_mapping import featureless
from training.songs import encoded, song

MODELS = {m.family: m for m in load_manifest(Settings().models_dir[0]).models}
pytestmark = pytest.mark.skipif(
    not {"translator", "fast", "dance"} <= set(MODELS),
    reason=f"needs the shipped translator, fast and dance models in {Settings().models_dir[0]}",
)
RIGS = ("fixture/words", "fixture/everything", "convention/Reallusion CC/iClone",
        "convention/Maya _JNT")  # fmt: skip


@pytest.fixture(scope="module")
def corpus() -> dict[str, rigs.CorpusRig]:
    fixture = rigs.load_fixture()
    out = {k: v for k, v in rigs.layout_variants("fixture", fixture).items() if k in RIGS}
    for name in ("Reallusion CC/iClone", "Maya _JNT"):
        out[f"convention/{name}"] = rigs.convention_rig(fixture, name)
    return out


def styles(family: str) -> list[str]:
    return sorted(MODELS[family].extra.get("styles", {})) if family in MODELS else []


def assert_same_rig(text: str, sent: bytes) -> None:
    a, b = bvh.loads(sent), bvh.loads(text)
    assert b.skeleton.names == a.skeleton.names
    assert b.skeleton.channels == a.skeleton.channels
    np.testing.assert_allclose(b.skeleton.offsets, a.skeleton.offsets, atol=1e-4)
    assert b.num_frames == a.num_frames and abs(b.fps - a.fps) < 1e-3
    assert np.all(np.isfinite(b.lrot)) and np.all(np.isfinite(b.lpos))


@pytest.mark.parametrize("name", RIGS)
def test_transfer_and_stylize_keep_the_rig(shared_client, corpus, name):
    item = corpus[name]
    sent = bvh.dumps(item.motion).encode()
    content = {"content": ("rig.bvh", sent, "text/plain")}
    r = shared_client.post(
        "/v1/transfer?format=json",
        files=content,
        data={"style_name": styles("translator")[0], "time_warp": "false"},  # frames kept
    )
    assert r.status_code == 200, r.text[:500]
    body = r.json()
    assert_same_rig(body["bvh"], sent)
    assert body["rig"]["method"] == item.method and 0 < body["rig"]["confidence"] <= 1
    mapped = {k: item.origin.get(v) for k, v in body["rig"]["mapping"].items()}
    assert mapped["UpperLeg_L"] == "LeftUpLeg" and mapped["Hand_R"] == "RightHand"
    r = shared_client.post(
        "/v1/stylize", files=content, data={"style_name": styles("fast")[-1], "time_warp": "false"}
    )
    assert r.status_code == 200, r.text[:500]
    assert_same_rig(r.text, sent)


@pytest.mark.parametrize("name", RIGS)
def test_style_code_reads_a_style_on_any_rig(shared_client, corpus, name):
    sent = bvh.dumps(corpus[name].motion).encode()
    r = shared_client.post("/v1/style-code", files={"style": ("s.bvh", sent, "text/plain")})
    assert r.status_code == 200, r.text[:500]
    body = r.json()
    assert len(body["code"]) > 0 and body["nearest"]


def test_dance_comes_on_any_rig(shared_client, corpus):
    data = encoded(song(6.0, bpm=120.0, seed=3), "WAV")
    samples, sr = audio_decode.decode(data)
    for name in ("fixture/everything", "convention/Reallusion CC/iClone"):
        sent = bvh.dumps(corpus[name].motion).encode()
        r = shared_client.post(
            "/v1/dance?format=json",
            files={
                "audio": ("s.wav", data, "audio/wav"),
                "skeleton": ("r.bvh", sent, "text/plain"),
            },
            data={"fps": "24"},
        )
        assert r.status_code == 200, r.text[:500]
        out, ref = bvh.loads(r.json()["bvh"]), bvh.loads(sent)
        assert out.skeleton.names == ref.skeleton.names and abs(out.fps - 24.0) < 1e-3
        assert out.num_frames == math.ceil(len(samples) / sr * 24 - 1e-9)
        assert r.json()["rig"]["method"] == corpus[name].method


def still_rig() -> bytes:
    """A rig with numbered bones standing in its rest pose: no toes, straight knees."""
    one = featureless(rigs.load_fixture())
    many = one.replace(lrot=np.repeat(one.lrot, 30, axis=0), lpos=np.repeat(one.lpos, 30, axis=0))
    return bvh.dumps(many).encode()


def test_an_ambiguous_rig_gets_a_422_that_says_how_to_pass_a_mapping(shared_client):
    sent = still_rig()
    content = {"content": ("still.bvh", sent, "text/plain")}
    for path, field in (
        ("/v1/transfer", styles("translator")[0]),
        ("/v1/stylize", styles("fast")[0]),
    ):
        r = shared_client.post(path, files=content, data={"style_name": field})
        body = assert_problem(r, 422, "unusable-input")
        assert "left from right" in body["detail"]
        assert {pair["limbs"] for pair in body["ambiguous"]} == {"legs", "arms"}
        assert all(len(pair["chains"]) == 2 for pair in body["ambiguous"])
        assert "mapping" in body["mapping_help"] and body["mapping_example"]
    # the example, sent back as the mapping, settles it
    r = shared_client.post(
        "/v1/transfer?format=json",
        files=content,
        data={
            "style_name": styles("translator")[0],
            "time_warp": "false",
            "mapping": json.dumps(body["mapping_example"]),
        },
    )
    assert r.status_code == 200, r.text[:500]
    assert_same_rig(r.json()["bvh"], sent)
    assert r.json()["rig"]["mapping"]["UpperLeg_L"] == body["mapping_example"]["UpperLeg_L"]


def shared_layouts() -> dict[str, bytes]:
    """The start of one file per skeleton of each shared data set (names and scale)."""
    from tests.conftest import DATA_DIR
    from tests.unit.test_rig_mapping import head_of

    out, seen = {}, set()
    for path in sorted(DATA_DIR.rglob("*.bvh")) if DATA_DIR.exists() else []:
        m = head_of(path, 60)
        scale = np.log10(max(np.ptp(m.skeleton.rest_positions(), axis=0).max(), 1e-9))
        key = (path.parent, m.skeleton.names, round(scale / 2))  # 1/128 scale apart
        if key not in seen:
            seen.add(key)
            out[str(path.relative_to(DATA_DIR))] = bvh.dumps(m).encode()
    return out


def test_every_shared_skeleton_goes_through_every_endpoint(shared_client):
    layouts = shared_layouts()
    if not layouts:
        pytest.skip("shared data not available (set MOTION_DATA_DIR)")
    wav = encoded(song(3.0, bpm=120.0, seed=5), "WAV")
    for name, sent in layouts.items():
        content = {"content": ("c.bvh", sent, "text/plain")}
        r = shared_client.post(
            "/v1/transfer",
            files=content,
            data={"style_name": styles("translator")[1], "time_warp": "false"},
        )
        assert r.status_code == 200, (name, r.text[:300])
        assert_same_rig(r.text, sent)
        fields = {"style_name": styles("fast")[1], "time_warp": "false"}  # frames kept
        r = shared_client.post("/v1/stylize", files=content, data=fields)
        assert r.status_code == 200, (name, r.text[:300])
        assert_same_rig(r.text, sent)
        r = shared_client.post("/v1/style-code", files={"style": ("s.bvh", sent, "text/plain")})
        assert r.status_code == 200, (name, r.text[:300])
        r = shared_client.post(
            "/v1/dance",
            files={"audio": ("a.wav", wav, "audio/wav"), "skeleton": ("r.bvh", sent, "text/plain")},
        )
        assert r.status_code == 200, (name, r.text[:300])
        assert bvh.loads(r.text).skeleton.names == bvh.loads(sent).skeleton.names
    assert len(layouts) >= 6, sorted(layouts)

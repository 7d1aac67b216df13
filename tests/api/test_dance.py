"""``POST /v1/dance`` against the real app with a tiny dance bundle exported here (random
weights: these tests check the plumbing, timing and errors, not the dancing)."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
import soundfile

from motion import bvh
from motion import canonical as C
from motion import dance_features as DF
from service.config import Settings
from tests.api.helpers import assert_problem
from tests.rigs import FIXTURE

torch = pytest.importorskip("torch")

SR = 22050


@pytest.fixture(scope="module")
def models_dir(tmp_path_factory) -> Path:
    from model_export import dance as ED
    from motion import dance_features as DF
    from training import dance as TD

    folder = tmp_path_factory.mktemp("models")
    (folder / "manifest.json").write_text('{"schema_version": 1, "models": []}')
    torch.manual_seed(0)
    model = TD.DanceNet(TD.Config(hidden=32, code=16, audio_hidden=32)).eval()
    rng = np.random.default_rng(0)
    stats = DF.DanceStats(
        np.full(DF.AUDIO_CHANNELS, -40.0, np.float32),
        np.full(DF.AUDIO_CHANNELS, 20.0, np.float32),
        np.zeros(DF.MOTION_CHANNELS, np.float32),
        np.full(DF.MOTION_CHANNELS, 0.05, np.float32),
    )
    poses = np.zeros((4, DF.MOTION_CHANNELS), np.float32)
    poses[:, DF.ROTATIONS] = np.tile([1, 0, 0, 0, 1, 0], len(DF.BODY))  # identity rotations
    poses[:, DF.HEIGHT] = 1.1
    poses += 0.01 * rng.standard_normal(poses.shape).astype(np.float32)
    stats = DF.DanceStats(stats.audio_mean, stats.audio_std, poses.mean(0), stats.motion_std)
    ED.export_bundle(model, stats, poses, folder)
    return folder


@pytest.fixture(scope="module")
def client(models_dir):
    import warnings

    from service.main import create_app

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*starlette.testclient.*")
        from fastapi.testclient import TestClient

    app = create_app(Settings(models_dir=models_dir, max_audio_seconds=30.0))
    with TestClient(app) as c:
        assert app.state.registry.wait(60)
        assert app.state.registry.ready, app.state.registry.reasons()
        yield c


def click_wav(seconds: float = 4.0, bpm: float = 120.0, fmt: str = "WAV") -> bytes:
    t = np.arange(int(seconds * SR)) / SR
    y = 0.05 * np.sin(2 * np.pi * 220 * t)
    for c in np.arange(0.25, seconds, 60 / bpm):
        i = int(c * SR)
        n = np.arange(min(400, len(y) - i))
        y[i : i + len(n)] += 0.6 * np.sin(2 * np.pi * 1000 * n / SR) * np.exp(-n / 80)
    buf = io.BytesIO()
    soundfile.write(buf, y.astype(np.float32), SR, format=fmt)
    return buf.getvalue()


def post(client, data: bytes, name="song.wav", media="audio/wav", query="", files=None, **form):
    return client.post(
        "/v1/dance" + query,
        files={"audio": (name, data, media), **(files or {})},
        data={k: str(v) for k, v in form.items()},
    )


def test_dance_lasts_as_long_as_the_audio(client):
    r = post(client, click_wav(4.0), genre="waltz")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain")
    assert "attachment" in r.headers["content-disposition"]
    motion = bvh.loads(r.text)
    assert motion.num_frames == 120 == int(r.headers["x-frames"])
    assert abs(motion.fps - 30.0) < 1e-3 and r.headers["x-fps"] == "30"
    assert motion.skeleton.names == C.JOINTS
    assert np.all(np.isfinite(motion.lrot)) and np.all(np.isfinite(motion.lpos))
    assert r.headers["x-model-version"].startswith("dance-dwm/")


@pytest.mark.parametrize("seconds", [0.05, 0.1, 0.3, 0.5, 0.9])
def test_a_song_of_under_a_second_dances_all_of_it(client, seconds):
    r = post(client, click_wav(seconds), genre="tango", query="?format=json")
    assert r.status_code == 200, r.text
    assert r.json()["frames"] == math.ceil(seconds * 30 - 1e-9)


def test_fps_json_and_predicted_genre(client):
    r = post(client, click_wav(3.1, fmt="FLAC"), name="s.flac", media="audio/flac",
             query="?format=json", fps=24)  # fmt: skip
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["frames"] == math.ceil(3.1 * 24) and body["fps"] == 24
    assert any("predicted" in w for w in body["warnings"])
    assert bvh.loads(body["bvh"]).num_frames == body["frames"]
    assert {"features", "network", "step", "motion"} <= set(body["timings_ms"])


def test_the_answer_says_the_genre_tempo_and_beat_alignment(client):
    """A dance says what it danced to, in headers on a BVH and in ``dance`` in JSON; a
    beat alignment is not a warning, so a dance with its genre given and a clear beat has
    none, and one whose genre was predicted says so in ``X-Warnings``."""
    song = click_wav(8.0, bpm=120.0)
    r = post(client, song, genre="cha-cha")
    assert r.status_code == 200, r.text
    assert r.headers["x-dance-genre"] == "cha-cha"
    assert abs(float(r.headers["x-dance-tempo"]) - 120.0) < 3.0
    score, chance = (float(r.headers[h]) for h in ("x-beat-alignment", "x-beat-alignment-chance"))
    assert 0.0 <= chance < score <= 1.0
    assert "x-warnings" not in r.headers
    body = post(client, song, query="?format=json").json()
    assert body["dance"]["genre_given"] is False and body["dance"]["genre"] in DF.GENRES
    assert body["dance"]["tempo_bpm"] > 0
    assert json.loads(post(client, song).headers["x-warnings"]) == body["warnings"]
    assert any("predicted" in w for w in body["warnings"])
    assert not any("alignment" in w for w in body["warnings"])


def test_seed_gives_variation_and_is_reproducible(client):
    song = click_wav(2.0)
    a, b, c = (post(client, song, genre="rumba", seed=s).text for s in (1, 1, 2))
    assert a == b
    assert a != c


def test_retargets_onto_a_skeleton(client):
    rig = Path(FIXTURE).read_bytes()
    r = post(client, click_wav(2.0), files={"skeleton": ("rig.bvh", rig, "text/plain")},
             genre="cha-cha", fps=60)  # fmt: skip
    assert r.status_code == 200, r.text
    out, ref = bvh.loads(r.text), bvh.loads(rig)
    assert out.skeleton.names == ref.skeleton.names
    assert out.num_frames == 120 and abs(out.fps - 60) < 1e-3
    # the skeleton may also come as a text field; "auto" asks for the predicted genre
    r = post(client, click_wav(1.0), skeleton=rig.decode(), genre="auto", query="?format=json")
    assert r.status_code == 200, r.text
    assert bvh.loads(r.json()["bvh"]).skeleton.names == ref.skeleton.names
    assert any("predicted" in w for w in r.json()["warnings"])


def test_errors_are_problems(client):
    body = assert_problem(post(client, click_wav(1.0), genre="polka"), 400, "invalid-request")
    assert "waltz" in body["genres"]
    silent = io.BytesIO()
    soundfile.write(silent, np.zeros(SR, np.float32), SR, format="WAV")
    assert_problem(post(client, silent.getvalue()), 422, "unusable-input")
    assert_problem(post(client, b"not audio at all" * 10), 400, "invalid-input")
    assert_problem(post(client, b"HIERARCHY", media="text/plain"), 415)
    assert_problem(post(client, click_wav(31.0)), 413, "too-large")
    assert_problem(post(client, b""), 400)


def test_styles_lists_dance_genres(client):
    styles = client.get("/v1/styles").json()["dance"]
    assert {s["name"] for s in styles} >= {"waltz", "rumba", "cha-cha", "tango"}
    manifest = client.get("/v1/models").json()
    text = json.dumps(manifest)
    assert "dance-dwm" in text


def test_a_bundle_whose_8_bit_step_fails_on_this_cpu_serves_the_float_one_and_says_so(
    client, models_dir, tmp_path
):
    """What a CPU whose kernels round the 8-bit graph differently would see: here, another
    network's 8-bit step graph in the bundle, listed with its hash."""
    import shutil
    import warnings

    from model_export import dance as ED
    from model_export import manifest as MF
    from service.main import create_app
    from training import dance as TD

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*starlette.testclient.*")
        from fastapi.testclient import TestClient

    assert client.get("/v1/models").json()["models"][0]["warnings"] == []
    folder, other = tmp_path / "models", tmp_path / "other"
    shutil.copytree(models_dir, folder)
    (other / "dance").mkdir(parents=True)
    torch.manual_seed(1)
    ED.export_graphs(
        TD.DanceNet(TD.Config(hidden=32, code=16, audio_hidden=32)).eval(), other / "dance"
    )
    ED.quantise_step(other / "dance")
    shutil.copyfile(other / "dance" / "step.onnx", folder / "dance" / "step.onnx")
    entry = json.loads((folder / "manifest.json").read_text())["models"][0]
    entry["files"] = [f["path"] for f in entry["files"]]
    MF.put_entry(entry, folder)  # hashed again: the registry loads it
    app = create_app(Settings(models_dir=folder, max_audio_seconds=30.0))
    with TestClient(app) as c:
        assert app.state.registry.wait(60) and app.state.registry.ready
        (model,) = c.get("/v1/models").json()["models"]
        assert model["status"] == "ready" and len(model["warnings"]) == 1
        assert "serving the float one" in model["warnings"][0]
        engine = app.state.registry.engines[model["name"]]
        assert engine.step_weights == "float" and set(engine.sessions) == {"audio", "step"}
        assert post(c, click_wav(4.0)).status_code == 200


def test_a_dance_from_features_computed_once_is_the_dance_from_the_song(models_dir):
    """An evaluation dances one song dozens of times from features it computed once: the
    engine must make the same dance from them as from the song, and must use them."""
    from service.engines.dance import DanceJob, song_features
    from service.metrics import StageTimer
    from training.eval_dance import load_engine

    engine, _ = load_engine(models_dir)
    samples, sr = soundfile.read(io.BytesIO(click_wav(3.0, bpm=120.0)), dtype="float32")
    other, _ = soundfile.read(io.BytesIO(click_wav(3.0, bpm=75.0)), dtype="float32")

    def dance(**features):
        job = DanceJob(samples, sr, genre="waltz", seed=3, **features)
        return engine.predict(job, StageTimer(engine.name))

    plain, given = dance(), dance(features=song_features(samples, sr))
    np.testing.assert_array_equal(given.motion.lrot, plain.motion.lrot)
    np.testing.assert_array_equal(given.motion.lpos, plain.motion.lpos)
    assert given.tempo == plain.tempo
    elsewhere = dance(features=song_features(other, sr))
    assert elsewhere.tempo != plain.tempo
    assert not np.array_equal(elsewhere.motion.lrot, plain.motion.lrot)


def test_the_bound_rollout_is_the_plain_loop_of_the_step_graph(models_dir):
    """The rollout binds the step graph's inputs and outputs to buffers once, for speed;
    its dance must be, bit for bit, the one a plain loop of ``session.run`` makes."""
    from motion import dance_features as DF
    from service.engines.dance import NOISE
    from training.eval_dance import load_engine

    engine, _ = load_engine(models_dir)
    rng = np.random.default_rng(5)
    frames = 40
    code = np.abs(rng.standard_normal((frames, 16))).astype(np.float32)
    genre = DF.genre_vector("tango")
    start = rng.standard_normal(DF.MOTION_CHANNELS).astype(np.float32)

    noise_rng = np.random.default_rng(9)
    noise = (NOISE * noise_rng.standard_normal((frames, DF.MOTION_CHANNELS))).astype(np.float32)
    noise[:, DF.CONTACTS] = 0.0
    zeros = np.zeros((1, engine.hidden), np.float32)
    feeds = {"genre": genre[None], "h1": zeros, "c1": zeros, "h2": zeros, "c2": zeros}
    want, prev = [start], start[None]
    for t in range(1, frames):
        feeds["code"], feeds["prev"] = code[t : t + 1], prev + noise[t]
        prev, feeds["h1"], feeds["c1"], feeds["h2"], feeds["c2"] = engine.sessions["step"].run(
            None, feeds
        )
        want.append(prev[0])
    got = engine.rollout(code, genre, start, 9)
    np.testing.assert_array_equal(got, np.stack(want))
    assert np.abs(got[1:] - start).max() > 1e-3  # it moved: the states were fed back

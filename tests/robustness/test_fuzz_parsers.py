"""Fuzzing the three readers of client files: ``motion.bvh.loads``, ``motion.keypoints.load``,
``motion.audio_decode.decode``. Whatever the bytes, each returns a valid object or raises
``MotionError`` with a known kind, and never takes long (:func:`time_limit` per call, plus a
5 s hypothesis deadline). Inputs: random bytes, and valid seed files (``corpus``) mutated at
the text, token, JSON, zip and byte level.
"""

from __future__ import annotations

import json
import math
import re
import zipfile

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from motion import audio_decode, bvh, keypoints
from motion.errors import MotionError
from motion.skeleton import Motion
from tests.robustness import corpus
from tests.robustness.fuzzing import fuzz_settings, time_limit

KINDS = {"invalid", "unusable", "too-large", "unsupported"}
LIMIT_S = 10.0


def parse_or_refuse(parse, data, **kwargs):
    """``parse(data)``, or None when it raised a MotionError of a known kind."""
    with time_limit(LIMIT_S, parse.__module__ + "." + parse.__name__):
        try:
            return parse(data, **kwargs)
        except MotionError as exc:
            assert exc.kind in KINDS, exc.kind
            assert isinstance(exc.message, str) and exc.message
            assert "Traceback" not in exc.message
            return None


# --- BVH ------------------------------------------------------------------------------------


def assert_valid_motion(motion: Motion) -> None:
    frames, joints = motion.lrot.shape[:2]
    assert frames >= 1 and joints >= 1
    assert motion.lpos.shape == (frames, joints, 3)
    assert np.isfinite(motion.lrot).all() and np.isfinite(motion.lpos).all()
    assert np.allclose(np.linalg.norm(motion.lrot, axis=-1), 1.0, atol=1e-6)
    assert math.isfinite(motion.fps) and 0 < motion.fps <= 10_000
    parents = motion.skeleton.parents
    assert parents[0] == -1 and all(0 <= p < j for j, p in enumerate(parents) if j)
    # what we read, we can write and read back
    again = bvh.loads(bvh.dumps(motion))
    assert again.num_frames == frames and again.skeleton.names == motion.skeleton.names


SPECIAL_TOKENS = [
    "nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e999", "9" * 400, "0", "-0", "1e-320",
    "0x1F", "", "1.5.5", "999999999999999999999", "-1", "{", "}", "ROOT", "JOINT", "End",
    "CHANNELS", "OFFSET", "MOTION", "Frames:", "Xrotation", "Xposition", "\x00", "\u2028",
]  # fmt: skip


@st.composite
def mutated_bvh(draw) -> bytes:
    text = draw(st.sampled_from(corpus.bvh_seeds()))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["token", "token", "line-del", "line-dup", "line-swap",
                                   "line-ins", "truncate", "header"]))  # fmt: skip
        lines = text.split("\n")
        if op == "token":
            tokens = re.split(r"(\s+)", text)
            i = draw(st.integers(0, len(tokens) - 1))
            tokens[i] = draw(st.sampled_from(SPECIAL_TOKENS) | st.text(max_size=6))
            text = "".join(tokens)
        elif op == "line-del":
            del lines[draw(st.integers(0, len(lines) - 1))]
            text = "\n".join(lines)
        elif op == "line-dup":
            i = draw(st.integers(0, len(lines) - 1))
            lines[i:i] = [lines[i]] * draw(st.integers(1, 500))
            text = "\n".join(lines)
        elif op == "line-swap":
            i, j = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            text = "\n".join(lines)
        elif op == "line-ins":
            lines.insert(draw(st.integers(0, len(lines))), draw(st.text(max_size=40)))
            text = "\n".join(lines)
        elif op == "truncate":
            text = text[: draw(st.integers(0, len(text)))]
        else:  # the two header numbers
            value = draw(st.sampled_from(SPECIAL_TOKENS) | st.integers().map(str))
            key = draw(st.sampled_from(["Frames:", "Frame Time:"]))
            text = re.sub(rf"{key}\s*\S+", f"{key} {value}", text)
    data = text.encode("utf-8", "surrogatepass")
    for _ in range(draw(st.integers(0, 2))):  # and the odd flipped bit
        i = draw(st.integers(0, max(0, len(data) - 1)))
        if data:
            data = data[:i] + bytes([data[i] ^ (1 << draw(st.integers(0, 7)))]) + data[i + 1 :]
    return data


@fuzz_settings(150)
@given(data=st.binary(max_size=2000) | st.text(max_size=500).map(str.encode))
def test_bvh_random_input(data: bytes) -> None:
    motion = parse_or_refuse(bvh.loads, data)
    if motion is not None:
        assert_valid_motion(motion)


@fuzz_settings(400)
@given(data=mutated_bvh())
def test_bvh_mutated_files(data: bytes) -> None:
    motion = parse_or_refuse(bvh.loads, data)
    if motion is not None:
        assert_valid_motion(motion)


@pytest.mark.parametrize("name", list(corpus.hostile_bvh()))
def test_bvh_hostile_corpus(name: str) -> None:
    motion = parse_or_refuse(bvh.loads, corpus.hostile_bvh()[name])
    if motion is not None:
        assert_valid_motion(motion)


# --- keypoints ------------------------------------------------------------------------------


def assert_valid_keypoints(kp) -> None:
    frames = kp.positions.shape[0]
    assert frames >= 2 and kp.positions.shape[1:] == (22, 2)
    assert np.isfinite(kp.positions).all() and np.isfinite(kp.confidence).all()
    assert math.isfinite(kp.fps) and 0 < kp.fps <= 1000
    try:
        normal = keypoints.normalize(kp)
    except MotionError as exc:
        assert exc.kind in KINDS
    else:
        assert np.isfinite(normal).all()


SPECIAL_VALUES = [
    float("nan"), float("inf"), -float("inf"), 1e308, -1e308, 1e-320, 0, -1, 10**30, "300",
    None, [], {}, [1, 2], True, "x" * 1000,
]  # fmt: skip


@st.composite
def mutated_keypoint_doc(draw):
    """A JSON document of frames with a few values, keys or frames changed."""
    frames = [corpus.keypoint_frame(i) for i in range(draw(st.integers(2, 6)))]
    for _ in range(draw(st.integers(1, 5))):
        op = draw(st.sampled_from(["value", "value", "drop-key", "people", "dup", "meta"]))
        frame = frames[draw(st.integers(0, len(frames) - 1))]
        people = frame.get("people")
        if op == "value" and isinstance(people, list) and people and isinstance(people[0], dict):
            points = people[0].get("pose_keypoints_2d")
            if isinstance(points, list) and points:
                points[draw(st.integers(0, len(points) - 1))] = draw(
                    st.sampled_from(SPECIAL_VALUES) | st.floats()
                )
        elif op == "drop-key":
            key = draw(st.sampled_from(["people", "version"]))
            frame.pop(key, None)
        elif op == "people":
            person = people[0] if isinstance(people, list) and people else {}
            frame["people"] = draw(
                st.sampled_from([[], [{}], [{"pose_keypoints_2d": []}], "x", None])
                | st.lists(st.just(person), max_size=20)
            )
        elif op == "dup":
            frames.extend([frame] * draw(st.integers(1, 50)))
    doc: object = frames
    if draw(st.booleans()):
        doc = {"frames": frames}
        for key in draw(st.lists(st.sampled_from(["fps", "layout", "image_size"]), max_size=3)):
            doc[key] = draw(st.sampled_from(SPECIAL_VALUES + ["coco17", "body25", [640, 480]]))
    return doc


@fuzz_settings(150)
@given(doc=mutated_keypoint_doc())
def test_keypoints_mutated_json(doc) -> None:
    kp = parse_or_refuse(keypoints.load, json.dumps(doc).encode())
    if kp is not None:
        assert_valid_keypoints(kp)


@st.composite
def mutated_keypoint_zip(draw) -> bytes:
    count = draw(st.integers(1, 8))
    names = draw(
        st.lists(
            st.sampled_from(
                [
                    "{i:03d}.json",
                    "v/f_{i:012d}_keypoints.json",
                    "{i}.JSON",
                    "__MACOSX/._{i}.json",
                    ".hidden{i}.json",
                    "n{i}.txt",
                    "../{i}.json",
                    "a/b/{i}.json",
                    "{i}.zip",
                ]
            )  # fmt: skip
            | st.text(min_size=1, max_size=12).map(lambda s: s + ".json"),
            min_size=count,
            max_size=count,
        )
    )
    files = {}
    for i, pattern in enumerate(names):
        name = pattern.replace("{i:03d}", f"{i:03d}").replace("{i:012d}", f"{i:012d}")
        name = name.replace("{i}", str(i))
        content = json.dumps(corpus.keypoint_frame(i)).encode()
        if draw(st.integers(0, 5)) == 0:
            content = draw(st.sampled_from([b"", b"{", b"[]", b"null", corpus.keypoint_zip(2)]))
        files[name] = content
    method = draw(st.sampled_from([zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2]))
    try:
        raw = corpus.make_zip(files, method)
    except Exception:  # a name zipfile itself refuses to write (the reader is what we test)
        raw = corpus.keypoint_zip(3)
    if draw(st.booleans()):
        raw = corpus.make_zip({"outer.json": raw}) if draw(st.booleans()) else raw
    for _ in range(draw(st.integers(0, 3))):  # damage: flipped bits or a cut
        if draw(st.booleans()):
            i = draw(st.integers(0, len(raw) - 1))
            raw = raw[:i] + bytes([raw[i] ^ 0xFF]) + raw[i + 1 :]
        else:
            raw = raw[: draw(st.integers(4, len(raw)))]
    return raw


@fuzz_settings(150)
@given(raw=mutated_keypoint_zip())
def test_keypoints_mutated_zip(raw: bytes) -> None:
    kp = parse_or_refuse(keypoints.load, raw)
    if kp is not None:
        assert_valid_keypoints(kp)


@fuzz_settings(100)
@given(raw=st.binary(max_size=1000), prefix=st.sampled_from([b"", b"PK\x03\x04", b"[", b"{"]))
def test_keypoints_random_bytes(raw: bytes, prefix: bytes) -> None:
    kp = parse_or_refuse(keypoints.load, prefix + raw)
    if kp is not None:
        assert_valid_keypoints(kp)


@pytest.mark.parametrize("name", list(corpus.hostile_keypoints()))
def test_keypoints_hostile_corpus(name: str) -> None:
    kp = parse_or_refuse(keypoints.load, corpus.hostile_keypoints()[name])
    if kp is not None:
        assert_valid_keypoints(kp)


# --- audio ----------------------------------------------------------------------------------


def assert_valid_audio(decoded) -> None:
    samples, sr = decoded
    assert isinstance(samples, np.ndarray) and samples.dtype == np.float32 and samples.ndim == 1
    assert samples.size > 0 and np.isfinite(samples).all()
    assert float(np.abs(samples).max()) <= audio_decode.MAX_ABS_SAMPLE
    assert audio_decode.MIN_SAMPLE_RATE <= sr <= audio_decode.MAX_SAMPLE_RATE


@st.composite
def mutated_audio(draw) -> bytes:
    seeds = corpus.audio_seeds()
    raw = bytearray(seeds[draw(st.sampled_from(sorted(seeds)))])
    for _ in range(draw(st.integers(1, 6))):
        op = draw(st.sampled_from(["flip", "flip", "header", "truncate", "splice", "repeat"]))
        if not raw:
            break
        if op == "flip":
            i = draw(st.integers(0, len(raw) - 1))
            raw[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "header":  # overwrite a few bytes where the headers are
            i = draw(st.integers(0, min(len(raw), 96) - 1))
            chunk = draw(st.binary(min_size=1, max_size=4))
            raw[i : i + len(chunk)] = chunk
        elif op == "truncate":
            raw = raw[: draw(st.integers(1, len(raw)))]
        elif op == "splice":
            i = draw(st.integers(0, len(raw)))
            raw[i:i] = draw(st.binary(max_size=64))
        else:
            raw = raw * 2
    return bytes(raw)


@fuzz_settings(200)
@given(raw=mutated_audio())
def test_audio_mutated_files(raw: bytes) -> None:
    decoded = parse_or_refuse(audio_decode.decode, raw, max_seconds=60.0)
    if decoded is not None:
        assert_valid_audio(decoded)


@fuzz_settings(150)
@given(
    channels=st.sampled_from([0, 1, 2, 3, 255, 65535]),
    sr=st.sampled_from([0, 1, 3999, 8000, 44100, 384001, 2**31, 2**32 - 1]),
    bits=st.sampled_from([0, 1, 7, 8, 12, 16, 24, 32, 64, 65535]),
    fmt_tag=st.sampled_from([0, 1, 3, 6, 7, 0x11, 0xFFFE, 0xFFFF]),
    data_size=st.none() | st.sampled_from([0, 1, 2**31, 2**32 - 1]),
    payload=st.binary(max_size=512),
)
def test_audio_wav_headers(channels, sr, bits, fmt_tag, data_size, payload) -> None:
    raw = corpus.wav_header(
        channels=channels, sr=sr, bits=bits, fmt_tag=fmt_tag, data_size=data_size, payload=payload
    )
    decoded = parse_or_refuse(audio_decode.decode, raw, max_seconds=60.0)
    if decoded is not None:
        assert_valid_audio(decoded)


@fuzz_settings(100)
@given(
    raw=st.binary(max_size=2000),
    prefix=st.sampled_from(
        [b"", b"RIFF\x00\x10\x00\x00WAVE", b"fLaC", b"OggS", b"ID3", b"\xff\xfb"]
    ),
)
def test_audio_random_bytes(raw: bytes, prefix: bytes) -> None:
    decoded = parse_or_refuse(audio_decode.decode, prefix + raw, max_seconds=60.0)
    if decoded is not None:
        assert_valid_audio(decoded)


@pytest.mark.parametrize("name", list(corpus.hostile_audio()))
def test_audio_hostile_corpus(name: str) -> None:
    decoded = parse_or_refuse(audio_decode.decode, corpus.hostile_audio()[name], max_seconds=60.0)
    if decoded is not None:
        assert_valid_audio(decoded)


def test_audio_limit_stops_decoding_early() -> None:
    """A long file is refused at the limit, without decoding the rest."""
    long_wav = corpus.encode(corpus.tone(seconds=30.0), 8000, "WAV", "PCM_16")
    with time_limit(LIMIT_S), pytest.raises(MotionError) as info:
        audio_decode.decode(long_wav, max_seconds=1.0)
    assert info.value.kind == "too-large" and info.value.limit == 1.0

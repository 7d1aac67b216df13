"""motion.keypoints: reading OpenPose/COCO/MediaPipe keypoints, tracking, filling, mapping."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motion import canonical as C
from motion import keypoint_layouts, keypoints
from motion.errors import MotionError
from motion.keypoints import Keypoints2D
from tests.conftest import data_path

J = C.INDEX
FOLDERS = ("openpose-treadmill-27", "openpose-treadmill-32", "openpose-treadmill-95")
VIDEO_FPS = 24000 / 1001


def frame_files(folder: str) -> list[Path]:
    return sorted(data_path("keypoints", folder).glob("*.json"))


def make_zip(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, content in files.items():
            zf.writestr(name, content)
    return buf.getvalue()


def expect_error(kind: str, call, *words: str) -> MotionError:
    with pytest.raises(MotionError) as info:
        call()
    err = info.value
    assert err.kind == kind, (err.kind, err.message)
    assert err.message
    for word in words:
        assert word.lower() in err.message.lower(), err.message
    return err


# --- synthetic people --------------------------------------------------------------------

# A standing figure in image coordinates (y down), by body part, 100 px torso.
FIGURE = {
    "nose": (0, -130),
    "neck": (0, -100),
    "l_eye": (5, -135),
    "r_eye": (-5, -135),
    "l_ear": (10, -130),
    "r_ear": (-10, -130),
    "l_shoulder": (25, -100),
    "r_shoulder": (-25, -100),
    "l_elbow": (30, -45),
    "r_elbow": (-30, -45),
    "l_wrist": (32, 5),
    "r_wrist": (-32, 5),
    "mid_hip": (0, 0),
    "l_hip": (15, 0),
    "r_hip": (-15, 0),
    "l_knee": (17, 95),
    "r_knee": (-17, 95),
    "l_ankle": (18, 190),
    "r_ankle": (-18, 190),
    "l_toe": (28, 205),
    "r_toe": (-8, 205),
}
BODY25 = (
    "nose neck r_shoulder r_elbow r_wrist l_shoulder l_elbow l_wrist mid_hip r_hip r_knee "
    "r_ankle l_hip l_knee l_ankle r_eye l_eye r_ear l_ear l_toe l_toe l_ankle r_toe r_toe "
    "r_ankle"
).split()
COCO17 = (
    "nose l_eye r_eye l_ear r_ear l_shoulder r_shoulder l_elbow r_elbow l_wrist r_wrist "
    "l_hip r_hip l_knee r_knee l_ankle r_ankle"
).split()
COCO18 = (
    "nose neck r_shoulder r_elbow r_wrist l_shoulder l_elbow l_wrist r_hip r_knee r_ankle "
    "l_hip l_knee l_ankle r_eye l_eye r_ear l_ear"
).split()
MEDIAPIPE33 = (
    "nose l_eye l_eye l_eye r_eye r_eye r_eye l_ear r_ear nose nose l_shoulder r_shoulder "
    "l_elbow r_elbow l_wrist r_wrist l_wrist r_wrist l_wrist r_wrist l_wrist r_wrist "
    "l_hip r_hip l_knee r_knee l_ankle r_ankle l_ankle r_ankle l_toe r_toe"
).split()


def person(order: list[str], at=(300.0, 300.0), scale=1.0, conf=0.9) -> np.ndarray:
    """``(K, 3)`` points of FIGURE in the given keypoint order, placed at ``at``."""
    xy = np.array([FIGURE[name] for name in order], dtype=float) * scale + np.asarray(at)
    return np.concatenate([xy, np.full((len(order), 1), conf)], axis=1)


def openpose_frame(*people: np.ndarray) -> dict:
    return {"version": 1.3, "people": [{"pose_keypoints_2d": p.ravel().tolist()} for p in people]}


def dumps(obj) -> bytes:
    return json.dumps(obj).encode()


# --- real data ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def folder_27() -> Keypoints2D:
    return keypoints.load(data_path("keypoints", "openpose-treadmill-27"), fps=VIDEO_FPS)


@pytest.mark.parametrize("folder", FOLDERS)
def test_real_folder_loads_one_clean_track(folder: str) -> None:
    kp = keypoints.load(data_path("keypoints", folder), fps=VIDEO_FPS)
    assert kp.positions.shape == (90, 22, 2) and kp.confidence.shape == (90, 22)
    assert kp.layout == "openpose-body25" and kp.fps == pytest.approx(23.976, abs=1e-3)
    assert np.isfinite(kp.positions).all()
    assert ((kp.confidence >= 0) & (kp.confidence <= 1)).all()
    derived = [J[n] for n in ("joint_Root", "Spine", "Chest", "Shoulder_L", "Shoulder_R")]
    assert not kp.observed[derived].any() and kp.observed.sum() == 17
    assert (kp.confidence[:, derived] == 0).all()
    # y points up: head above hips above feet in (almost) every frame
    y = kp.positions[..., 1]
    assert (y[:, J["Head"]] > y[:, J["Hips"]]).mean() > 0.95
    assert (y[:, J["Hips"]] > np.maximum(y[:, J["Foot_L"]], y[:, J["Foot_R"]])).mean() > 0.95
    # the track never jumps: hips move little per frame relative to the body
    norm = keypoints.normalize(kp)
    steps = np.linalg.norm(np.diff(norm[:, J["Hips"]], axis=0), axis=-1)
    assert steps.max() < 0.3
    assert np.all(norm[:, J["joint_Root"], 1] <= norm[:, J["Hips"], 1])


def test_real_multi_person_frames_follow_the_walker(folder_27: Keypoints2D) -> None:
    # The data README says some frames hold several people: find them, check the tracker
    # took the walker (OpenPose lists it first here) and not a background detection.
    for folder in FOLDERS[:2]:
        files = frame_files(folder)
        docs = [json.loads(p.read_bytes()) for p in files]
        multi = [i for i, d in enumerate(docs) if len(d["people"]) > 1]
        assert len(multi) >= 10, (folder, multi)  # 27: 14 frames (3 with 3 people), 32: 13
        kp = folder_27 if folder.endswith("27") else keypoints.load(files[0].parent)
        for i in multi:
            walker = np.array(docs[i]["people"][0]["pose_keypoints_2d"]).reshape(25, 3)
            np.testing.assert_allclose(kp.positions[i, J["UpperLeg_L"]], walker[12, :2] * [1, -1])
            np.testing.assert_allclose(kp.positions[i, J["UpperArm_R"]], walker[2, :2] * [1, -1])
        # same result when the walker is listed last in every frame
        for d in docs:
            d["people"].reverse()
        swapped = keypoints.load(dumps(docs))
        np.testing.assert_allclose(swapped.positions, kp.positions)


def test_real_zip_variants_match_folder(folder_27: Keypoints2D) -> None:
    files = frame_files("openpose-treadmill-27")
    plain = {p.name: p.read_bytes() for p in files}
    long_names = {f"video_{int(p.stem):012d}_keypoints.json": p.read_bytes() for p in files}
    variants = {
        "flat": plain | {"SOURCES.md": b"# notes", "__MACOSX/._000.json": b"junk"},
        "subfolder": {f"json_inputs/27/{n}": c for n, c in plain.items()},
        "long names in folder": {f"out/{n}": c for n, c in reversed(long_names.items())},
    }
    for label, entries in variants.items():
        kp = keypoints.load(make_zip(entries), fps=VIDEO_FPS)
        assert kp.positions.shape == (90, 22, 2), label
        np.testing.assert_allclose(kp.positions, folder_27.positions, err_msg=label)
        np.testing.assert_allclose(kp.confidence, folder_27.confidence, err_msg=label)


def test_real_json_list_and_document_match_folder(folder_27: Keypoints2D, tmp_path) -> None:
    docs = [json.loads(p.read_bytes()) for p in frame_files("openpose-treadmill-27")]
    from_list = keypoints.load(dumps(docs), fps=VIDEO_FPS)
    np.testing.assert_allclose(from_list.positions, folder_27.positions)
    as_text = keypoints.load(json.dumps(docs), fps=VIDEO_FPS)
    np.testing.assert_allclose(as_text.positions, folder_27.positions)
    document = {"fps": VIDEO_FPS, "layout": "BODY_25", "frames": docs}
    (tmp_path / "clip.json").write_bytes(dumps(document))
    from_doc = keypoints.load(tmp_path / "clip.json")
    assert from_doc.fps == pytest.approx(VIDEO_FPS) and from_doc.layout == "openpose-body25"
    np.testing.assert_allclose(from_doc.positions, folder_27.positions)
    # OpenPose JSON carries no frame rate: 30 unless told
    assert keypoints.load(dumps(docs)).fps == 30.0


def test_real_normalize_is_resolution_independent(folder_27: Keypoints2D) -> None:
    docs = [json.loads(p.read_bytes()) for p in frame_files("openpose-treadmill-27")]
    for d in docs:
        for p in d["people"]:
            pts = np.array(p["pose_keypoints_2d"]).reshape(-1, 3)
            pts[:, :2] *= 2.5
            p["pose_keypoints_2d"] = pts.ravel().tolist()
    big = keypoints.load(dumps(docs))
    a, b = keypoints.normalize(folder_27), keypoints.normalize(big)
    np.testing.assert_allclose(a, b, atol=1e-9)
    torso = np.linalg.norm(a[:, J["Neck"]] - a[:, J["Hips"]], axis=-1)
    assert np.median(torso) == pytest.approx(1.0)
    assert np.abs(a[:, J["Hips"]].mean(axis=0)).max() < 1e-9


def test_image_size_flips_y_into_the_image() -> None:
    frames = [openpose_frame(person(BODY25, at=(300, 300 + i))) for i in range(3)]
    kp = keypoints.load(dumps(frames), image_size=(720, 720))
    assert kp.image_size == (720.0, 720.0)
    np.testing.assert_allclose(kp.positions[:, J["UpperLeg_L"], 1], [420, 419, 418])


# --- layouts -----------------------------------------------------------------------------


def check_figure(kp: Keypoints2D, at=(300.0, 300.0), scale=1.0, height=0.0) -> None:
    """Canonical joints land on the right body parts of FIGURE (y flipped)."""

    def expect(*parts: str) -> np.ndarray:
        xy = np.mean([FIGURE[p] for p in parts], axis=0) * scale + np.asarray(at)
        return np.array([xy[0], height - xy[1]])

    hip_joints, shoulders = expect("l_hip", "r_hip"), expect("l_shoulder", "r_shoulder")
    torso = shoulders - hip_joints
    centres = {  # the canonical joints sit above the detector's hip joints and shoulders
        "Hips": hip_joints + keypoint_layouts.HIPS_ABOVE_HIP_JOINTS * torso,
        "Neck": shoulders + keypoint_layouts.NECK_ABOVE_SHOULDERS * torso,
    }
    head = expect("l_ear", "r_ear") - shoulders
    centres["Head"] = centres["Neck"] + keypoint_layouts.HEAD_FROM_NECK * np.linalg.norm(
        torso
    ) * head / np.linalg.norm(head)
    for joint, xy in centres.items():
        np.testing.assert_allclose(kp.positions[0, J[joint]], xy, err_msg=joint)
    table = {
        "UpperArm_L": ("l_shoulder",),
        "LowerArm_L": ("l_elbow",),
        "Hand_L": ("l_wrist",),
        "UpperArm_R": ("r_shoulder",),
        "Hand_R": ("r_wrist",),
        "UpperLeg_L": ("l_hip",),
        "LowerLeg_L": ("l_knee",),
        "Foot_L": ("l_ankle",),
        "LowerLeg_R": ("r_knee",),
        "Foot_R": ("r_ankle",),
    }
    for joint, parts in table.items():
        np.testing.assert_allclose(kp.positions[0, J[joint]], expect(*parts), err_msg=joint)
    hips, neck = kp.positions[0, J["Hips"]], kp.positions[0, J["Neck"]]
    np.testing.assert_allclose(kp.positions[0, J["Spine"]], hips + 0.38 * (neck - hips))
    np.testing.assert_allclose(kp.positions[0, J["Chest"]], hips + 0.60 * (neck - hips))
    assert kp.positions[0, J["joint_Root"], 0] == pytest.approx(hips[0])
    assert kp.positions[0, J["joint_Root"], 1] == pytest.approx(expect("l_ankle")[1])


def test_coco17_maps_and_derives_toes() -> None:
    frames = [[person(COCO17, conf=0.8).ravel().tolist()] for _ in range(3)]
    kp = keypoints.load(dumps(frames))
    assert kp.layout == "coco17"
    check_figure(kp)
    np.testing.assert_allclose(kp.positions[:, J["Toes_L"]], kp.positions[:, J["Foot_L"]])
    assert not kp.observed[J["Toes_L"]] and kp.observed[J["LowerLeg_L"]]
    assert (kp.confidence[:, J["Toes_L"]] == 0).all()
    assert kp.confidence[0, J["LowerLeg_L"]] == pytest.approx(0.8)
    # [x, y] only (34 numbers, e.g. from a detector), nested [[x, y], ...] too
    xy_only = [person(COCO17)[:, :2].ravel().tolist() for _ in range(3)]
    kp2 = keypoints.load(dumps(xy_only), layout="COCO-17")
    check_figure(kp2)
    assert kp2.confidence[0, J["LowerLeg_L"]] == 1.0
    nested = [person(COCO17)[:, :2].tolist() for _ in range(3)]
    np.testing.assert_allclose(keypoints.load(dumps(nested)).positions, kp2.positions)


def test_coco18_and_body25_map() -> None:
    kp18 = keypoints.load(dumps([openpose_frame(person(COCO18))] * 2))
    assert kp18.layout == "openpose-coco18"
    check_figure(kp18)
    kp25 = keypoints.load(dumps([openpose_frame(person(BODY25))] * 2))
    check_figure(kp25)
    np.testing.assert_allclose(kp25.positions[0, J["Toes_L"]], [328, -505])
    assert kp25.observed[J["Toes_L"]] and kp25.confidence[0, J["Toes_L"]] > 0


def test_mediapipe33_normalised_coordinates() -> None:
    def landmarks() -> list[list[float]]:
        pts = person(MEDIAPIPE33, at=(0.5, 0.5), scale=0.002)
        z = np.zeros((33, 1))
        return np.concatenate([pts[:, :2], z, pts[:, 2:]], axis=1).tolist()

    kp = keypoints.load(dumps({"layout": "mediapipe", "frames": [landmarks()] * 4}))
    assert kp.layout == "mediapipe-pose33" and kp.image_size == (1.0, 1.0)
    check_figure(kp, at=(0.5, 0.5), scale=0.002, height=1.0)
    np.testing.assert_allclose(kp.positions[0, J["Toes_L"]], [0.5 + 0.056, 1 - 0.91])
    # MediaPipe's own landmark objects
    objs = [[{"x": x, "y": y, "z": z, "visibility": v} for x, y, z, v in landmarks()]] * 4
    np.testing.assert_allclose(keypoints.load(dumps(objs)).positions, kp.positions)


# --- tracking and filling ----------------------------------------------------------------


def test_tracker_follows_one_person_when_list_order_swaps() -> None:
    frames = []
    for i in range(30):
        walker = person(BODY25, at=(200 + 2 * i, 300))  # the larger, seen first
        other = person(BODY25, at=(600 - 3 * i, 320), scale=0.7, conf=0.7)
        people = [walker, other] if i % 2 else [other, walker]
        if i in (12, 13, 14):
            people = [other]  # the walker is missing: do not jump to the other one
        frames.append(openpose_frame(*people))
    kp = keypoints.load(dumps(frames))
    hips_x = kp.positions[:, J["Hips"], 0]
    np.testing.assert_allclose(hips_x, 200 + 2 * np.arange(30))  # gap interpolated
    assert (kp.confidence[12:15, J["Hips"]] == 0).all()
    assert (kp.confidence[[11, 15], J["Hips"]] > 0).all()


def test_missing_points_interpolate_linearly_and_hold_at_ends() -> None:
    frames = []
    for i in range(10):
        pts = person(BODY25, at=(100 + 10 * i, 300))
        if i in (0, 4, 5, 6, 9):
            pts[BODY25.index("l_knee")] = [0, 0, 0]  # OpenPose's "missing"
        if i == 7:
            pts[BODY25.index("l_wrist"), 2] = 0.01  # below the confidence threshold
        frames.append(openpose_frame(pts))
    kp = keypoints.load(dumps(frames))
    knee = kp.positions[:, J["LowerLeg_L"], 0]
    expected = 117 + 10 * np.arange(10.0)
    expected[0], expected[9] = expected[1], expected[8]  # ends hold the nearest value
    np.testing.assert_allclose(knee, expected)
    np.testing.assert_array_equal(
        kp.confidence[:, J["LowerLeg_L"]] == 0, np.isin(np.arange(10), [0, 4, 5, 6, 9])
    )
    assert kp.positions[7, J["Hand_L"], 0] == pytest.approx(132 + 70)
    assert kp.confidence[7, J["Hand_L"]] == 0


def test_never_seen_joints_are_derived_with_zero_confidence() -> None:
    frames = []
    for _ in range(5):
        pts = person(COCO17)
        for part in ("l_wrist", "l_elbow", "r_hip", "l_ear", "r_ear"):
            pts[COCO17.index(part)] = [0, 0, 0]
        frames.append([pts.ravel().tolist()])
    kp = keypoints.load(dumps(frames))
    assert np.isfinite(kp.positions).all()
    for joint in ("Hand_L", "LowerArm_L", "UpperLeg_R"):
        assert (kp.confidence[:, J[joint]] == 0).all(), joint
    pos = kp.positions[0]
    # the missing hip mirrors the seen one through the detector's mid-hip, here the one hip
    # seen (the canonical Hips then sit above it)
    np.testing.assert_allclose(pos[J["UpperLeg_R"]], pos[J["UpperLeg_L"]])
    assert pos[J["Hips"], 1] > pos[J["UpperLeg_L"], 1]
    assert pos[J["Hand_L"], 1] < pos[J["LowerArm_L"], 1] < pos[J["UpperArm_L"], 1]
    # the head points from the shoulders to the mid of the eyes, at the canonical distance
    head = pos[J["Head"]] - pos[J["Neck"]]
    assert head[0] == pytest.approx(0.0) and head[1] > 0


def test_file_number_gap_is_a_missing_frame() -> None:
    files = {
        f"{i:03d}.json": dumps(openpose_frame(person(BODY25, at=(100 + i, 300)))) for i in (0, 1, 3)
    }
    kp = keypoints.load(make_zip(files))
    assert kp.num_frames == 4
    np.testing.assert_allclose(kp.positions[:, J["Hips"], 0], [100, 101, 102, 103])
    assert kp.confidence[2, J["Hips"]] == 0


def test_keypoints2d_is_read_only_and_checked() -> None:
    kp = keypoints.load(dumps([openpose_frame(person(BODY25))] * 2))
    with pytest.raises(ValueError):
        kp.positions[0, 0, 0] = 1.0
    with pytest.raises(MotionError):
        Keypoints2D(np.zeros((2, 21, 2)), np.zeros((2, 21)), np.zeros(21, bool), 30.0, "x")


# --- malformed input ---------------------------------------------------------------------

GOOD_FRAME = openpose_frame(person(BODY25))


def _zip_with(name: str, content: bytes) -> bytes:
    return make_zip({"000.json": dumps(GOOD_FRAME), name: content})


MALFORMED = {
    "empty bytes": (b"", "invalid", "empty"),
    "blank text": ("   ", "invalid", "empty"),
    "not json": (b"hello, keypoints", "invalid", "json"),
    "binary junk": (b"\xff\xfe\x00\x81garbage", "invalid", "utf-8"),
    "json number": (b"42", "invalid", "list of frames"),
    "object without frames": (b'{"foo": 1}', "invalid", "frames"),
    "frames not a list": (b'{"frames": 3}', "invalid", "frames"),
    "people not a list": (dumps([{"people": 5}] * 2), "invalid", "people"),
    "frame with 7 numbers": (dumps([[1, 2, 3, 4, 5, 6, 7]] * 2), "invalid", "7 numbers"),
    "strings as values": (
        dumps([{"people": [{"pose_keypoints_2d": ["a"] * 75}]}] * 2),
        "invalid",
        "numbers",
    ),
    "ragged nested": (dumps([[[1, 2], [1, 2, 3]]] * 2), "invalid", "nested"),
    "unknown count": (dumps([[1.0] * 60] * 2), "unsupported", "60 numbers"),
    "counts disagree": (dumps([[1.0] * 75, [1.0] * 51]), "invalid", "disagree"),
    "deeply nested": (b"[" * 100000 + b"]" * 100000, "invalid", "json"),
    "zip without json": (make_zip({"readme.txt": b"hi"}), "invalid", "no .json"),
    "zip in zip": (_zip_with("inner.zip", make_zip({"a.json": b"[]"})), "invalid", "nested"),
    "zip disguised as json": (
        _zip_with("001.json", make_zip({"a.json": b"[]"})),
        "invalid",
        "nested",
    ),
    "zip with ..": (_zip_with("../001.json", dumps(GOOD_FRAME)), "invalid", "unsafe"),
    "zip two folders": (
        make_zip({"a/000.json": dumps(GOOD_FRAME), "b/001.json": dumps(GOOD_FRAME)}),
        "invalid",
        "more than one folder",
    ),
    "zip bad frame": (_zip_with("001.json", b"{oops"), "invalid", "001.json"),
    "zip duplicate frame": (
        make_zip({"a_001.json": dumps(GOOD_FRAME), "b_001.json": dumps(GOOD_FRAME)}),
        "invalid",
        "frame 1",
    ),
    "truncated zip": (make_zip({"000.json": dumps(GOOD_FRAME)})[:40], "invalid", "zip"),
    "no people anywhere": (dumps([{"version": 1.3, "people": []}] * 5), "unusable", "no person"),
    "one frame with a person": (dumps([GOOD_FRAME] + [{"people": []}] * 4), "unusable", "only 1"),
    "single frame": (dumps(GOOD_FRAME), "unusable", "2 frames"),
    "no torso": (dumps([[0.0] * 75] * 3), "unusable", "no person"),
}


@pytest.mark.parametrize("label", list(MALFORMED))
def test_malformed_input_raises_motion_error(label: str) -> None:
    data, kind, word = MALFORMED[label]
    expect_error(kind, lambda: keypoints.load(data), word)


def test_bad_arguments_raise_motion_error(tmp_path) -> None:
    good = dumps([GOOD_FRAME] * 3)
    expect_error("unsupported", lambda: keypoints.load(good, layout="halpe26"), "halpe26")
    expect_error("invalid", lambda: keypoints.load(good, layout="coco17"), "17 points")
    expect_error("invalid", lambda: keypoints.load(good, fps=0), "fps")
    expect_error("invalid", lambda: keypoints.load(dumps({"fps": "x", "frames": []})), "fps")
    expect_error("invalid", lambda: keypoints.load(good, image_size=(0, 5)), "image_size")
    expect_error("invalid", lambda: keypoints.load(12345), "bytes")
    expect_error("invalid", lambda: keypoints.load(tmp_path / "nope"), "no such")
    expect_error("invalid", lambda: keypoints.load(tmp_path), "no .json")


def test_limits_raise_too_large(tmp_path) -> None:
    frames = [GOOD_FRAME] * 12
    files = {f"{i:03d}.json": dumps(f) for i, f in enumerate(frames)}
    for p, c in files.items():
        (tmp_path / p).write_bytes(c)
    cases = {
        "json list": dumps(frames),
        "document": dumps({"frames": frames}),
        "zip": make_zip(files),
        "folder": tmp_path,
    }
    for label, data in cases.items():
        err = expect_error("too-large", lambda d=data: keypoints.load(d, max_frames=10), "limit")
        assert err.limit == 10, label
        expect_error("too-large", lambda d=data: keypoints.load(d, max_bytes=2000), "limit")
    assert keypoints.load(make_zip(files), max_frames=12).num_frames == 12
    # a small zip that declares more uncompressed bytes than allowed (a zip bomb)
    bomb = make_zip({"000.json": b"[" + b" " * 300_000 + b"]", "001.json": dumps(GOOD_FRAME)})
    assert len(bomb) < 5000
    expect_error("too-large", lambda: keypoints.load(bomb, max_bytes=100_000), "unpacks")


def test_real_folder_limits() -> None:
    folder = data_path("keypoints", "openpose-treadmill-27")
    expect_error("too-large", lambda: keypoints.load(folder, max_frames=50), "90")
    expect_error("too-large", lambda: keypoints.load(folder, max_bytes=10_000), "bytes")


_json = st.recursive(
    st.none() | st.booleans() | st.integers(-10, 10**6) | st.floats() | st.text(max_size=5),
    lambda kids: (
        st.lists(kids, max_size=8)
        | st.dictionaries(
            st.sampled_from(["people", "frames", "pose_keypoints_2d", "fps", "layout", "x", "y"]),
            kids,
            max_size=4,
        )
    ),
    max_leaves=40,
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(doc=_json)
def test_fuzzed_json_only_ever_raises_motion_error(doc) -> None:
    try:
        kp = keypoints.load(json.dumps(doc).encode())
    except MotionError:
        return
    assert np.isfinite(kp.positions).all()


@settings(max_examples=60, deadline=None)
@given(blob=st.binary(max_size=300))
def test_fuzzed_bytes_only_ever_raise_motion_error(blob: bytes) -> None:
    for data in (blob, b"PK\x03\x04" + blob):
        with pytest.raises(MotionError):
            keypoints.load(data)


def test_joint_centre_offsets_are_the_canonical_skeletons():
    rest = C.SKELETON.rest_positions()
    y = {name: rest[C.INDEX[name], 1] for name in C.JOINTS}
    hip_joints = 0.5 * (y["UpperLeg_L"] + y["UpperLeg_R"])
    shoulders = 0.5 * (y["UpperArm_L"] + y["UpperArm_R"])
    torso = shoulders - hip_joints
    head = np.linalg.norm(rest[C.INDEX["Head"]] - rest[C.INDEX["Neck"]])
    assert keypoint_layouts.HIPS_ABOVE_HIP_JOINTS == pytest.approx(
        (y["Hips"] - hip_joints) / torso, abs=1e-3
    )
    assert keypoint_layouts.NECK_ABOVE_SHOULDERS == pytest.approx(
        (y["Neck"] - shoulders) / torso, abs=1e-3
    )
    assert keypoint_layouts.HEAD_FROM_NECK == pytest.approx(head / torso, abs=1e-3)


def test_a_zip_entry_without_a_name_is_skipped() -> None:
    """zipfile's own ``is_dir`` fails on an entry whose name is empty (the fuzz test found
    one): such an entry is passed over like a folder, and the frames load."""
    frames = {f"{i:03d}.json": dumps(GOOD_FRAME) for i in range(3)}
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr(zipfile.ZipInfo(""), b"{}")  # writestr("") refuses; a hostile file need not
        for name, content in frames.items():
            zf.writestr(name, content)
    loaded = keypoints.load(buf.getvalue())
    assert loaded.num_frames == keypoints.load(make_zip(frames)).num_frames == 3

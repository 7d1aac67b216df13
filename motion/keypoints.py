"""2D keypoints of a video (OpenPose, COCO, MediaPipe) as one person on the canonical joints.

``load`` reads what a pose detector writes (a zip or a folder of per-frame OpenPose JSON
files, or one JSON document), follows ONE person through the clip, fills the points it
missed and maps its layout onto the 22 canonical joints. ``normalize`` turns the result
into the resolution-independent numbers the 2D style encoder sees.

Glossary of the arrays (F frames, K source keypoints, 22 canonical joints):

- ``points (K, 3)``: one detected person as ``(x, y, confidence)`` in the detector's
  image coordinates (y pointing down); confidence 0 marks a missing point;
- ``track (F, K, 3)``: the followed person over the clip, all zeros where absent;
- ``Keypoints2D.positions (F, 22, 2)``: canonical joints, y pointing UP.

Conventions and choices, stated once:

- y is flipped: ``y_up = height - y`` when the image height is known (argument,
  document field, or ``1.0`` for coordinates normalised to 0..1), else ``y_up = -y``
  (as deep-motion-editing does). x is kept as is. Units stay those of the input.
- A point is *valid* when its confidence is >= ``min_confidence`` (default 0.05), its
  coordinates are finite and of sane size (< 1e7), and it is not exactly ``(0, 0)``
  (OpenPose's "missing").
- Missing points are filled per source keypoint by linear interpolation over time,
  holding the nearest valid value before the first and after the last valid frame;
  filled points get confidence 0.
- Joints the layout does not observe (Spine, Chest, Shoulder_L/R, joint_Root; Toes for
  COCO layouts) are derived, see ``_derive``; their confidence is 0 and
  ``Keypoints2D.observed`` is False for them.

One module though long: reading, tracking, filling and mapping share these conventions
and the hostile-input checks, and split apart they would each restate them.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from motion.errors import MotionError

# The canonical skeleton's joints (Bandai order). Another module will own the canonical
# skeleton; keep this tuple so it can be swapped for an import.
CANONICAL_JOINTS: tuple[str, ...] = (
    "joint_Root",
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "Shoulder_L",
    "UpperArm_L",
    "LowerArm_L",
    "Hand_L",
    "Shoulder_R",
    "UpperArm_R",
    "LowerArm_R",
    "Hand_R",
    "UpperLeg_L",
    "LowerLeg_L",
    "Foot_L",
    "Toes_L",
    "UpperLeg_R",
    "LowerLeg_R",
    "Foot_R",
    "Toes_R",
)
_J = {name: i for i, name in enumerate(CANONICAL_JOINTS)}

DEFAULT_FPS = 30.0
DEFAULT_MAX_FRAMES = 20000
DEFAULT_MAX_BYTES = 64 * 1024 * 1024
DEFAULT_MIN_CONFIDENCE = 0.05

# Fractions measured on the Bandai data (median over 15 takes, global positions):
# Spine and Chest lie at 0.383 and 0.602 of the Hips->Neck segment, Shoulder_L/R at
# 0.53 of Neck->UpperArm, Head 0.157 torso lengths above the Neck. The limb lengths
# (in torso lengths, Hips->Neck) place joints that are never seen.
SPINE_FRACTION = 0.38
CHEST_FRACTION = 0.60
SHOULDER_FRACTION = 0.53
_HEAD_ABOVE_NECK = 0.16
_UPPER_ARM = 0.59
_FOREARM = 0.54
_THIGH = 0.95
_SHIN = 1.0

# Detectors mark the hip joints and the shoulder line; the canonical Hips sit above the
# hip joints, the Neck above the shoulder line and the Head at a fixed distance from the
# Neck. In lengths of the detector's torso (hip-joint midpoint to shoulder midpoint), on
# the canonical rest pose (tests check them against motion.canonical): left at the
# detector's points, the 2D style input was 5-7 standard deviations off the training
# data's for these joints (their offsets from the Hips hardly vary in 3D motion).
HIPS_ABOVE_HIP_JOINTS = 0.055
NECK_ABOVE_SHOULDERS = 0.084
HEAD_FROM_NECK = 0.162

_MAX_COORD = 1e7
_SEED_FRAMES = 10
_MISSING_PENALTY = 0.5
_GATE = 0.5
_GATE_PER_GAP = 0.1
_GATE_MAX = 2.0
_MIN_OVERLAP = 0.3

_NUMBER_TYPES = (int, float, type(None))
_NUMBER_TYPE_SET = frozenset(_NUMBER_TYPES)  # exact types: bool and str are not numbers here
_PERSON_KEYS = ("pose_keypoints_2d", "keypoints", "landmarks", "pose_landmarks")
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06", b"PK\x07\x08")
_ARCHIVE_SUFFIXES = (".zip", ".tar", ".gz", ".tgz", ".bz2", ".xz", ".7z", ".rar")


@dataclass(frozen=True)
class _Layout:
    """A detector's keypoint layout and its recipe for the canonical joints.

    ``recipe`` maps a canonical joint to alternatives, best first; an alternative is a
    tuple of source keypoint indices whose mean gives the joint.
    """

    name: str
    count: int
    recipe: dict[str, tuple[tuple[int, ...], ...]]


def _limbs(
    sh: int, el: int, wr: int, hip: int, kn: int, an: int, side: str
) -> dict[str, tuple[tuple[int, ...], ...]]:
    return {
        f"UpperArm_{side}": ((sh,),),
        f"LowerArm_{side}": ((el,),),
        f"Hand_{side}": ((wr,),),
        f"UpperLeg_{side}": ((hip,),),
        f"LowerLeg_{side}": ((kn,),),
        f"Foot_{side}": ((an,),),
    }


def _pair(a: int, b: int) -> tuple[tuple[int, ...], ...]:
    """Mid of two points, else either one."""
    return ((a, b), (a,), (b,))


# BODY_25: 0 Nose, 1 Neck, 2 RShoulder, 3 RElbow, 4 RWrist, 5 LShoulder, 6 LElbow,
# 7 LWrist, 8 MidHip, 9 RHip, 10 RKnee, 11 RAnkle, 12 LHip, 13 LKnee, 14 LAnkle, 15 REye,
# 16 LEye, 17 REar, 18 LEar, 19 LBigToe, 20 LSmallToe, 21 LHeel, 22 RBigToe, 23 RSmallToe,
# 24 RHeel.
_BODY25 = _Layout(
    "openpose-body25",
    25,
    {
        "Hips": ((8,),) + _pair(9, 12),
        "Neck": ((1,),) + _pair(2, 5),
        "Head": _pair(17, 18) + _pair(15, 16) + ((0,),),
        **_limbs(5, 6, 7, 12, 13, 14, "L"),
        **_limbs(2, 3, 4, 9, 10, 11, "R"),
        "Toes_L": ((19,), (20,)),
        "Toes_R": ((22,), (23,)),
    },
)
# OpenPose COCO-18: 0 Nose, 1 Neck, 2 RShoulder, 3 RElbow, 4 RWrist, 5 LShoulder,
# 6 LElbow, 7 LWrist, 8 RHip, 9 RKnee, 10 RAnkle, 11 LHip, 12 LKnee, 13 LAnkle, 14 REye,
# 15 LEye, 16 REar, 17 LEar.
_COCO18 = _Layout(
    "openpose-coco18",
    18,
    {
        "Hips": _pair(8, 11),
        "Neck": ((1,),) + _pair(2, 5),
        "Head": _pair(16, 17) + _pair(14, 15) + ((0,),),
        **_limbs(5, 6, 7, 11, 12, 13, "L"),
        **_limbs(2, 3, 4, 8, 9, 10, "R"),
    },
)
# COCO-17 (detectors): 0 nose, 1 left_eye, 2 right_eye, 3 left_ear, 4 right_ear,
# 5 left_shoulder, 6 right_shoulder, 7 left_elbow, 8 right_elbow, 9 left_wrist,
# 10 right_wrist, 11 left_hip, 12 right_hip, 13 left_knee, 14 right_knee, 15 left_ankle,
# 16 right_ankle.
_COCO17 = _Layout(
    "coco17",
    17,
    {
        "Hips": _pair(11, 12),
        "Neck": _pair(5, 6),
        "Head": _pair(3, 4) + _pair(1, 2) + ((0,),),
        **_limbs(5, 7, 9, 11, 13, 15, "L"),
        **_limbs(6, 8, 10, 12, 14, 16, "R"),
    },
)
# MediaPipe Pose (BlazePose) 33: 0 nose, 1-3 left eye inner/eye/outer, 4-6 right eye,
# 7 left_ear, 8 right_ear, 9-10 mouth, 11 left_shoulder, 12 right_shoulder, 13/14 elbows,
# 15/16 wrists, 17-22 pinky/index/thumb, 23/24 hips, 25/26 knees, 27/28 ankles,
# 29/30 heels, 31 left_foot_index, 32 right_foot_index (left first in each pair).
_MEDIAPIPE33 = _Layout(
    "mediapipe-pose33",
    33,
    {
        "Hips": _pair(23, 24),
        "Neck": _pair(11, 12),
        "Head": _pair(7, 8) + _pair(2, 5) + ((0,),),
        **_limbs(11, 13, 15, 23, 25, 27, "L"),
        **_limbs(12, 14, 16, 24, 26, 28, "R"),
        "Toes_L": ((31,),),
        "Toes_R": ((32,),),
    },
)
LAYOUTS: dict[str, _Layout] = {lay.name: lay for lay in (_BODY25, _COCO18, _COCO17, _MEDIAPIPE33)}
_BY_COUNT = {lay.count: lay for lay in LAYOUTS.values()}
_ALIASES = {
    "openposebody25": "openpose-body25",
    "body25": "openpose-body25",
    "openpose": "openpose-body25",
    "openposecoco18": "openpose-coco18",
    "openposecoco": "openpose-coco18",
    "coco18": "openpose-coco18",
    "coco17": "coco17",
    "coco": "coco17",
    "mediapipepose33": "mediapipe-pose33",
    "mediapipe33": "mediapipe-pose33",
    "mediapipepose": "mediapipe-pose33",
    "mediapipe": "mediapipe-pose33",
    "blazepose": "mediapipe-pose33",
    "blazepose33": "mediapipe-pose33",
}


@dataclass(frozen=True, eq=False)
class Keypoints2D:
    """One person's 2D keypoints on the canonical joints (``CANONICAL_JOINTS`` order).

    ``positions (F, 22, 2)`` float64: input units (pixels, or 0..1 if the detector
    normalised), y pointing UP. ``confidence (F, 22)`` in [0, 1]: the detector's score,
    0 where a point was missing and filled and for derived joints. ``observed (22,)``
    bool: joints the source layout observes (directly or as a mean of observed points,
    e.g. Hips = mid of the hips in COCO). ``fps`` frames per second. ``layout`` the
    source layout name (``LAYOUTS``). ``image_size`` ``(width, height)`` in input units,
    or None when unknown. Arrays are copied and read-only.
    """

    positions: np.ndarray  # (F, 22, 2)
    confidence: np.ndarray  # (F, 22)
    observed: np.ndarray  # (22,)
    fps: float
    layout: str
    image_size: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        positions = np.array(self.positions, dtype=np.float64)
        confidence = np.array(self.confidence, dtype=np.float64)
        observed = np.array(self.observed, dtype=bool)
        n = len(CANONICAL_JOINTS)
        if positions.ndim != 3 or positions.shape[1:] != (n, 2):
            raise MotionError(f"keypoint positions must be (F, {n}, 2), got {positions.shape}")
        if confidence.shape != positions.shape[:2] or observed.shape != (n,):
            raise MotionError("keypoint confidence/observed shapes disagree with positions")
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise MotionError(f"fps must be a positive number, got {self.fps}")
        for arr in (positions, confidence, observed):
            arr.flags.writeable = False
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "confidence", confidence)
        object.__setattr__(self, "observed", observed)
        object.__setattr__(self, "fps", float(self.fps))

    @property
    def num_frames(self) -> int:
        return int(self.positions.shape[0])


# ---------------------------------------------------------------------------------------
# public API


def load(
    data: bytes | str | os.PathLike,
    *,
    fps: float | None = None,
    layout: str | None = None,
    image_size: tuple[float, float] | None = None,
    min_confidence: float = DEFAULT_MIN_CONFIDENCE,
    max_frames: int = DEFAULT_MAX_FRAMES,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> Keypoints2D:
    """Read 2D keypoints and return one tracked person on the canonical joints.

    ``data`` is the content (bytes, or a str that starts with ``{`` or ``[``) or a path
    to a file or a folder:

    - a zip of per-frame OpenPose JSON files (``000.json``,
      ``video_000000000012_keypoints.json``...), at its top or inside one folder;
      files are ordered by the last number in their names, a gap in the numbers is
      kept as frames without a person; other files (README, SOURCES.md) are ignored;
    - a folder of such files (not recursive);
    - one JSON document: a list of frames, or ``{"fps", "layout", "image_size",
      "frames": [...]}``; a frame is an OpenPose frame ``{"people": [...]}``, a list of
      people, or one person's keypoints as a flat ``[x, y, c, ...]``/``[x, y, ...]``
      array, a nested ``[[x, y, c], ...]`` array or MediaPipe's ``[{"x", "y",
      "visibility"}, ...]``; a person is such an array or a dict holding one under
      ``pose_keypoints_2d``/``keypoints``/``landmarks``. A zip or folder holding a single
      JSON file reads it as such a document.

    The layout is found from the keypoint count (25 OpenPose BODY_25, 18 OpenPose
    COCO, 17 COCO, 33 MediaPipe Pose) unless ``layout`` (or the document's "layout")
    names it; the argument wins over the document. ``fps`` likewise (default 30: OpenPose
    JSON carries none). ``image_size`` ``(width, height)`` only sets how y is flipped.

    Raises ``MotionError`` with kind ``"invalid"`` (malformed JSON/zip/structure, unsafe
    zip paths, nested archives), ``"unsupported"`` (a keypoint count or layout name we do
    not know), ``"too-large"`` (more than ``max_frames`` frames or ``max_bytes`` bytes,
    compressed or uncompressed) or ``"unusable"`` (a person in fewer than 2 frames, or
    the torso never seen).
    """
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 1:
        raise MotionError(f"max_frames must be a positive integer, got {max_frames!r}")
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 1:
        raise MotionError(f"max_bytes must be a positive integer, got {max_bytes!r}")
    if isinstance(min_confidence, bool) or not isinstance(min_confidence, (int, float)):
        raise MotionError(f"min_confidence must be a number, got {min_confidence!r}")
    thr = float(min_confidence)
    if not (0.0 <= thr <= 1.0):
        raise MotionError(f"min_confidence must lie in [0, 1], got {min_confidence}")
    raw_frames, meta = _read_source(data, max_frames, max_bytes)
    if len(raw_frames) > max_frames:
        raise MotionError(
            f"{len(raw_frames)} frames is over the limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    lay = _resolve_layout(layout if layout is not None else meta.get("layout"))
    fps_value = _check_fps(fps if fps is not None else meta.get("fps", DEFAULT_FPS))
    size = _check_image_size(image_size) if image_size is not None else meta.get("image_size")
    frames = [_parse_frame(frame, i, lay) for i, frame in enumerate(raw_frames)]
    lay = _detect_layout(frames, lay)
    frames = _clean(frames, lay.count, thr)
    if len(frames) < 2:
        raise MotionError(
            f"need at least 2 frames of keypoints, got {len(frames)}", kind="unusable"
        )
    track = _track(frames, lay.count)
    present = (track[..., 2] > 0).any(axis=1)
    if not present.any():
        raise MotionError("no person detected in any frame", kind="unusable")
    if present.sum() < 2:
        raise MotionError(
            f"a person is detected in only {int(present.sum())} of {len(frames)} frames;"
            " need at least 2",
            kind="unusable",
        )
    filled, seen = _fill(track)
    if size is None and _looks_normalised(track):
        size = (1.0, 1.0)
    positions, confidence, observed = _to_canonical(filled, track[..., 2], seen, present, lay)
    height = size[1] if size is not None else 0.0
    positions[..., 1] = height - positions[..., 1]
    _place_root(positions)
    return Keypoints2D(positions, confidence, observed, fps_value, lay.name, size)


def normalize(kp: Keypoints2D) -> np.ndarray:
    """Resolution-independent positions for the 2D style encoder: ``(F, 22, 2)``.

    Centred on the clip's mean Hips position (one offset for the whole clip, so the
    motion's global travel stays in the numbers, as the root trajectory does in
    aberman2020's 2D input; per-frame root-relative positions are ``out -
    out[:, 1:2]``) and divided by a robust body size: the median Neck-to-Hips length
    over the frames where both are observed (all frames if none). y points up.
    Raises ``MotionError`` (kind "unusable") when that size is zero.
    """
    pos = kp.positions
    if pos.shape[0] == 0:
        raise MotionError("cannot normalise keypoints: the clip has no frames", kind="unusable")
    hips, neck = pos[:, _J["Hips"]], pos[:, _J["Neck"]]
    torso = np.linalg.norm(neck - hips, axis=-1)
    seen = (kp.confidence[:, _J["Hips"]] > 0) & (kp.confidence[:, _J["Neck"]] > 0)
    size = float(np.median(torso[seen] if seen.any() else torso))
    extent = float(np.ptp(pos[..., 1]))
    if not np.isfinite(size) or size <= 1e-9 * max(1.0, extent):
        raise MotionError("cannot normalise keypoints: the torso has no length", kind="unusable")
    return (pos - hips.mean(axis=0)) / size


# ---------------------------------------------------------------------------------------
# reading: bytes, text, zip, folder -> list of raw frames + document metadata


def _read_source(data: Any, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
    if isinstance(data, (bytes, bytearray, memoryview)):
        return _read_bytes(bytes(data), max_frames, max_bytes)
    if isinstance(data, str):
        stripped = data.lstrip("\ufeff \t\r\n")
        if not stripped:
            raise MotionError("empty keypoint input")
        if stripped[0] in "[{":
            return _read_bytes(data.encode("utf-8"), max_frames, max_bytes)
        return _read_path(Path(data), max_frames, max_bytes)
    if isinstance(data, os.PathLike):
        return _read_path(Path(os.fspath(data)), max_frames, max_bytes)
    raise MotionError(f"keypoints must be bytes, JSON text or a path, not {type(data).__name__}")


def _read_path(path: Path, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
    try:
        if path.is_dir():
            return _read_folder(path, max_frames, max_bytes)
        if not path.is_file():
            raise MotionError(f"no such keypoint file or folder: {path}")
        if path.stat().st_size > max_bytes:
            raise MotionError(
                f"{path.name} is over the limit of {max_bytes} bytes",
                kind="too-large",
                limit=max_bytes,
            )
        raw = path.read_bytes()
    except MotionError:
        raise
    except OSError as exc:
        raise MotionError(f"cannot read {path}: {exc.strerror or exc}") from None
    except ValueError:  # e.g. a NUL character in the path
        raise MotionError("not a usable keypoint path") from None
    return _read_bytes(raw, max_frames, max_bytes)


def _read_bytes(raw: bytes, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
    if len(raw) > max_bytes:
        raise MotionError(
            f"keypoint input of {len(raw)} bytes is over the limit of {max_bytes}",
            kind="too-large",
            limit=max_bytes,
        )
    if not raw.strip():
        raise MotionError("empty keypoint input")
    if raw[:4] in _ZIP_MAGIC:
        return _read_zip(raw, max_frames, max_bytes)
    return _document(_loads(raw, "keypoint input"), max_frames)


def _loads(raw: bytes, what: str) -> Any:
    """JSON from bytes; every failure becomes a MotionError (kind "invalid")."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise MotionError(f"{what} is neither a zip archive nor UTF-8 JSON text") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise MotionError(
            f"{what} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}",
            line=exc.lineno,
        ) from None
    except RecursionError:
        raise MotionError(f"{what} is JSON nested too deeply") from None
    except ValueError as exc:  # e.g. an integer with more than 4300 digits
        raise MotionError(f"{what} is not usable JSON: {exc}") from None


def _document(doc: Any, max_frames: int) -> tuple[list[Any], dict]:
    """Frames and metadata of one JSON document (list of frames, or dict)."""
    meta: dict = {}
    if isinstance(doc, list):
        frames = doc
    elif isinstance(doc, dict):
        if "frames" in doc:
            frames = doc["frames"]
            if not isinstance(frames, list):
                raise MotionError('"frames" must be a list of frames')
            if doc.get("fps") is not None:
                meta["fps"] = doc["fps"]
            if doc.get("layout") is not None:
                meta["layout"] = doc["layout"]
            if doc.get("image_size") is not None:
                meta["image_size"] = _check_image_size(doc["image_size"])
            elif doc.get("width") is not None and doc.get("height") is not None:
                meta["image_size"] = _check_image_size((doc["width"], doc["height"]))
        elif "people" in doc:
            frames = [doc]
        else:
            raise MotionError(
                'a JSON object of keypoints needs "frames" (a list) or "people" (one frame)'
            )
    else:
        raise MotionError("keypoint JSON must be a list of frames or an object")
    if len(frames) > max_frames:
        raise MotionError(
            f"{len(frames)} frames is over the limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    return frames, meta


def _read_zip(raw: bytes, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
    try:
        zf = zipfile.ZipFile(io.BytesIO(raw))
        infos = zf.infolist()
    except (
        zipfile.BadZipFile,
        zipfile.LargeZipFile,
        OSError,
        ValueError,
        EOFError,
        NotImplementedError,  # e.g. an entry that needs a newer zip version than Python reads
    ):
        raise MotionError("keypoint input is not a readable zip archive") from None
    if len(infos) > max_frames + 1000:
        raise MotionError(
            f"zip archive holds {len(infos)} entries, over the limit",
            kind="too-large",
            limit=max_frames,
        )
    entries: list[zipfile.ZipInfo] = []
    for info in infos:
        name = info.filename.replace("\\", "/")
        parts = PurePosixPath(name).parts
        if name.startswith("/") or ".." in parts or re.match(r"^[A-Za-z]:", name):
            raise MotionError(f"zip entry {info.filename!r} has an unsafe path")
        if not parts or info.is_dir():  # an empty name has no last character to test
            continue
        base = parts[-1]
        if parts[0] == "__MACOSX" or base.startswith("."):
            continue
        if base.lower().endswith(_ARCHIVE_SUFFIXES):
            raise MotionError(f"zip entry {info.filename!r} is a nested archive; not accepted")
        if base.lower().endswith(".json"):
            if info.flag_bits & 0x1:
                raise MotionError(f"zip entry {info.filename!r} is encrypted")
            entries.append(info)
    if not entries:
        raise MotionError("zip archive holds no .json keypoint files")
    folders = {str(PurePosixPath(e.filename.replace("\\", "/")).parent) for e in entries}
    if len(folders) > 1:
        shown = ", ".join(sorted(folders)[:3])
        raise MotionError(f"zip archive holds JSON files in more than one folder ({shown})")
    if len(entries) > max_frames:
        raise MotionError(
            f"zip archive holds {len(entries)} frame files, over the limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    declared = sum(e.file_size for e in entries)
    if declared > max_bytes:
        raise MotionError(
            f"zip archive unpacks to {declared} bytes, over the limit of {max_bytes}",
            kind="too-large",
            limit=max_bytes,
        )
    budget = max_bytes
    contents: dict[str, bytes] = {}
    for info in entries:
        try:
            with zf.open(info) as fh:
                content = fh.read(budget + 1)
        except (
            zipfile.BadZipFile,
            zlib.error,
            OSError,
            EOFError,
            RuntimeError,
            ValueError,
            NotImplementedError,
        ) as exc:
            raise MotionError(f"cannot unpack zip entry {info.filename!r}: {exc}") from None
        if len(content) > budget:
            raise MotionError(
                f"zip archive unpacks to more than {max_bytes} bytes",
                kind="too-large",
                limit=max_bytes,
            )
        budget -= len(content)
        if content[:4] in _ZIP_MAGIC:
            raise MotionError(f"zip entry {info.filename!r} is a nested archive; not accepted")
        contents[PurePosixPath(info.filename.replace("\\", "/")).name] = content
    return _frames_from_files(contents, max_frames)


def _read_folder(path: Path, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
    files = [
        p
        for p in path.iterdir()
        if p.suffix.lower() == ".json" and not p.name.startswith(".") and p.is_file()
    ]
    if not files:
        raise MotionError(f"folder {path} holds no .json keypoint files")
    if len(files) > max_frames:
        raise MotionError(
            f"folder holds {len(files)} frame files, over the limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    total = sum(p.stat().st_size for p in files)
    if total > max_bytes:
        raise MotionError(
            f"folder holds {total} bytes of JSON, over the limit of {max_bytes}",
            kind="too-large",
            limit=max_bytes,
        )
    return _frames_from_files({p.name: p.read_bytes() for p in files}, max_frames)


def _frames_from_files(contents: dict[str, bytes], max_frames: int) -> tuple[list[Any], dict]:
    """Frames from per-frame files ``{file name: bytes}``; a single file is a document."""
    if len(contents) == 1:
        ((name, raw),) = contents.items()
        return _document(_loads(raw, name), max_frames)
    names = _order_frame_files(list(contents), max_frames)
    frames: list[Any] = []
    for name in names:
        if name is None:
            frames.append(None)
            continue
        frame = _loads(contents[name], f"frame file {name}")
        if not isinstance(frame, (dict, list)):
            raise MotionError(f"frame file {name} must hold a JSON object or list")
        frames.append(frame)
    return frames, {}


def _order_frame_files(names: list[str], max_frames: int) -> list[str | None]:
    """File names in frame order; ``None`` stands for a frame number with no file.

    Frames are numbered by the last run of digits in a name. Without numbers in every
    name, names are sorted naturally and no gaps are assumed.
    """
    numbers = {}
    for name in names:
        digits = re.findall(r"\d+", name)
        if not digits:
            break
        numbers[name] = int(digits[-1])
    else:
        by_number: dict[int, str] = {}
        for name, n in numbers.items():
            if n in by_number:
                raise MotionError(f"files {by_number[n]!r} and {name!r} both claim frame {n}")
            by_number[n] = name
        lo, hi = min(by_number), max(by_number)
        if hi - lo + 1 <= max_frames:
            return [by_number.get(n) for n in range(lo, hi + 1)]
        return [by_number[n] for n in sorted(by_number)]

    def natural(name: str) -> list:
        return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]

    return sorted(names, key=natural)


# ---------------------------------------------------------------------------------------
# parsing frames and people -> (K, 3) arrays


def _parse_frame(frame: Any, index: int, lay: _Layout | None) -> list[np.ndarray]:
    """One frame -> its people as ``(K, 3)`` arrays ``(x, y, confidence)``."""
    where = f"frame {index}"
    if frame is None:
        return []
    if isinstance(frame, dict):
        if "people" in frame:
            people = frame["people"]
            if people is None:
                return []
            if not isinstance(people, list):
                raise MotionError(f'{where}: "people" must be a list')
        elif any(k in frame for k in _PERSON_KEYS):
            people = [frame]
        else:
            raise MotionError(f'{where}: a frame object needs "people"')
    elif isinstance(frame, list):
        if not frame:
            return []
        people = [frame] if _is_point_array(frame) else frame
    else:
        raise MotionError(f"{where}: a frame must be an object or a list")
    out = []
    for j, person in enumerate(people):
        points = _parse_person(person, f"{where}, person {j}", lay)
        if points is not None:
            out.append(points)
    return out


def _is_point_array(value: list) -> bool:
    """True when ``value`` is one person's points rather than a list of people."""
    first = value[0]
    if isinstance(first, _NUMBER_TYPES) and not isinstance(first, bool):
        return True
    if isinstance(first, dict):
        return "x" in first and "y" in first
    return (
        isinstance(first, list)
        and 2 <= len(first) <= 4
        and all(isinstance(v, _NUMBER_TYPES) for v in first)
    )


def _parse_person(person: Any, where: str, lay: _Layout | None) -> np.ndarray | None:
    if isinstance(person, dict):
        key = next((k for k in _PERSON_KEYS if k in person), None)
        if key is None:
            raise MotionError(f"{where}: no {' / '.join(_PERSON_KEYS[:3])} array")
        person = person[key]
    if not isinstance(person, list):
        raise MotionError(f"{where}: keypoints must be an array")
    if not person:
        return None
    if set(map(type, person)) <= _NUMBER_TYPE_SET:
        return _from_flat(person, where, lay)
    if all(isinstance(v, dict) for v in person):
        rows = []
        for v in person:
            if "x" not in v or "y" not in v:
                raise MotionError(f'{where}: landmark objects need "x" and "y"')
            score = next((v[k] for k in ("visibility", "score", "confidence") if k in v), 1.0)
            rows.append([v["x"], v["y"], score])
        return _to_array(rows, 3, where)
    if all(isinstance(v, list) for v in person):
        width = len(person[0])
        if width not in (2, 3, 4) or any(len(v) != width for v in person):
            raise MotionError(
                f"{where}: nested keypoints must all be [x, y], [x, y, score] or"
                " [x, y, z, visibility]"
            )
        flat = [x for v in person for x in v]
        if not set(map(type, flat)) <= _NUMBER_TYPE_SET:
            raise MotionError(f"{where}: keypoint values must be numbers")
        return _to_array(flat, width, where)
    raise MotionError(f"{where}: keypoints must be numbers, [x, y, ...] arrays or objects")


def _from_flat(values: list, where: str, lay: _Layout | None) -> np.ndarray:
    n = len(values)
    if lay is not None:
        stride = n // lay.count if n % lay.count == 0 else 0
        if stride not in (2, 3, 4):
            raise MotionError(
                f"{where}: {n} numbers do not make {lay.count} points of layout {lay.name}"
            )
        return _to_array(values, stride, where)
    for stride in (3, 2, 4):
        if n % stride == 0 and n // stride in _BY_COUNT:
            return _to_array(values, stride, where)
    if n % 2 and n % 3:
        raise MotionError(f"{where}: {n} numbers are not a list of (x, y[, score]) points")
    known = ", ".join(str(c) for c in sorted(_BY_COUNT))
    raise MotionError(
        f"{where}: {n} numbers match no known keypoint layout ({known} points)",
        kind="unsupported",
    )


def _to_array(values: Sequence, stride: int, where: str) -> np.ndarray:
    """``(K, 3)`` float64 ``(x, y, confidence)`` from ``K * stride`` values."""
    try:
        arr = np.asarray(values, dtype=np.float64).reshape(-1, stride)
    except (TypeError, ValueError, OverflowError):
        raise MotionError(f"{where}: keypoint values must be numbers of sane size") from None
    out = np.ones((arr.shape[0], 3))
    out[:, :2] = arr[:, :2]
    if stride >= 3:
        out[:, 2] = arr[:, stride - 1]
    return out


def _clean(frames: list[list[np.ndarray]], k: int, thr: float) -> list[np.ndarray]:
    """Per frame a ``(P, K, 3)`` array of its people, confidence in [0, 1] and 0 (with
    xy 0) for invalid points (see the module docstring)."""
    counts = [len(people) for people in frames]
    flat = [p for people in frames for p in people]
    pts = np.stack(flat) if flat else np.zeros((0, k, 3))
    xy = pts[..., :2]
    with np.errstate(invalid="ignore"):
        conf = np.where(np.isnan(pts[..., 2]), 0.0, pts[..., 2]).clip(0.0, 1.0)
        bad = (
            ~np.isfinite(xy).all(axis=-1)
            | ~(np.abs(xy) < _MAX_COORD).all(axis=-1)
            | (xy == 0).all(axis=-1)
            | (conf < thr)
            | (conf <= 0)
        )
    out = np.where(bad[..., None], 0.0, pts)
    out[..., 2] = np.where(bad, 0.0, conf)
    return np.split(out, np.cumsum(counts)[:-1]) if counts else []


def _resolve_layout(name: Any) -> _Layout | None:
    if name is None:
        return None
    if not isinstance(name, str):
        raise MotionError(f"layout must be a name, got {name!r:.80}")
    key = _ALIASES.get(re.sub(r"[^a-z0-9]", "", name.lower()))
    if key is None:
        raise MotionError(
            f"unknown keypoint layout {name!r:.80}; known: {', '.join(LAYOUTS)}", kind="unsupported"
        )
    return LAYOUTS[key]


def _detect_layout(frames: list[list[np.ndarray]], lay: _Layout | None) -> _Layout:
    counts = {p.shape[0] for people in frames for p in people}
    if lay is not None:
        wrong = counts - {lay.count}
        if wrong:
            raise MotionError(
                f"layout {lay.name} has {lay.count} keypoints, the input has {min(wrong)}"
            )
        return lay
    if not counts:
        raise MotionError("no person detected in any frame", kind="unusable")
    if len(counts) > 1:
        raise MotionError(f"frames disagree on the number of keypoints ({sorted(counts)})")
    (count,) = counts
    if count not in _BY_COUNT:
        known = ", ".join(f"{c} ({x.name})" for c, x in sorted(_BY_COUNT.items()))
        raise MotionError(
            f"{count} keypoints per person match no known layout; known: {known}",
            kind="unsupported",
        )
    return _BY_COUNT[count]


def _as_float(value: Any) -> float:
    """A JSON number as a float; an integer too large for one becomes inf (not an error)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _check_fps(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MotionError(f"fps must be a number, got {value!r:.80}")
    fps = _as_float(value)
    if not (math.isfinite(fps) and 0 < fps <= 1000):
        raise MotionError(f"fps must lie in (0, 1000], got {fps:g}")
    return fps


def _check_image_size(value: Any) -> tuple[float, float]:
    if isinstance(value, dict) and "width" in value and "height" in value:
        value = (value["width"], value["height"])
    ok = (
        isinstance(value, (list, tuple))
        and len(value) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        and all(math.isfinite(_as_float(v)) and 0 < v < _MAX_COORD for v in value)
    )
    if not ok:
        raise MotionError(f"image_size must be [width, height] > 0, got {str(value)[:80]}")
    return (float(value[0]), float(value[1]))


def _looks_normalised(track: np.ndarray) -> bool:
    """True when every valid coordinate lies in [-0.5, 1.5] (detector gave 0..1 units)."""
    xy = track[..., :2][track[..., 2] > 0]
    return bool(xy.size) and bool(np.all((xy >= -0.5) & (xy <= 1.5)))


# ---------------------------------------------------------------------------------------
# tracking one person


def _track(frames: list[np.ndarray], k: int) -> np.ndarray:
    """Follow one person through the frames (each ``(P, K, 3)``): ``(F, K, 3)``, zeros
    where absent.

    The seed is the person with the largest total confidence x bounding-box diagonal
    in the first ``_SEED_FRAMES`` frames that hold anyone; from there the track runs
    forwards and backwards, each frame taking the candidate with the smallest mean
    joint distance (over joints seen in both, in units of the track's bounding-box
    diagonal) plus a penalty for the track's joints the candidate lacks. A candidate
    that shares too few joints or lies farther than a gate (which widens with the
    number of frames the person has been missing) is not taken: the person is absent
    in that frame.
    """
    num = len(frames)
    track = np.zeros((num, k, 3))
    best = (0.0, -1, -1)
    looked = 0
    for f, people in enumerate(frames):
        if looked >= _SEED_FRAMES:
            break
        if not len(people):
            continue
        looked += 1
        for p, points in enumerate(people):
            valid = points[:, 2] > 0
            if valid.sum() < 2:
                continue
            score = float(points[valid, 2].sum()) * _diagonal(points[valid, :2])
            if score > best[0]:
                best = (score, f, p)
    _, seed_frame, seed_person = best
    if seed_frame < 0:
        return track
    seed = frames[seed_frame][seed_person]
    track[seed_frame] = seed
    for order in (range(seed_frame + 1, num), range(seed_frame - 1, -1, -1)):
        ref_xy = seed[:, :2].copy()
        ref_valid = seed[:, 2] > 0
        scale = _diagonal(ref_xy[ref_valid]) or 1.0
        gap = 0
        for f in order:
            gap += 1
            if not len(frames[f]):
                continue
            chosen = _match(frames[f], ref_xy, ref_valid, scale, gap)
            if chosen is None:
                continue
            track[f] = chosen
            valid = chosen[:, 2] > 0
            ref_xy[valid] = chosen[valid, :2]
            ref_valid |= valid
            scale = _diagonal(ref_xy[ref_valid]) or 1.0
            gap = 0
    return track


def _match(
    people: np.ndarray, ref_xy: np.ndarray, ref_valid: np.ndarray, scale: float, gap: int
) -> np.ndarray | None:
    """The candidate of ``people (P, K, 3)`` that continues the track, or None.

    ``ref_xy (K, 2)`` last known position of each keypoint, ``ref_valid (K,)`` whether
    it has one, ``scale`` the body size, ``gap`` frames since the last match.
    """
    gate = min(_GATE + _GATE_PER_GAP * (gap - 1), _GATE_MAX)
    n_ref = int(ref_valid.sum())
    both = ref_valid & (people[..., 2] > 0)  # (P, K)
    n_both = both.sum(axis=1)
    dist = np.linalg.norm(people[..., :2] - ref_xy, axis=-1)  # (P, K)
    mean = (dist * both).sum(axis=1) / np.maximum(n_both, 1) / scale
    ok = (n_both >= max(2, _MIN_OVERLAP * n_ref)) & (mean <= gate)
    if not ok.any():
        return None
    cost = np.where(ok, mean + _MISSING_PENALTY * (1.0 - n_both / max(n_ref, 1)), np.inf)
    return people[int(np.argmin(cost))]


def _diagonal(xy: np.ndarray) -> float:
    """Bounding-box diagonal of points ``(N, 2)`` (0 for fewer than 2 points)."""
    if len(xy) < 2:
        return 0.0
    return float(np.linalg.norm(xy.max(axis=0) - xy.min(axis=0)))


# ---------------------------------------------------------------------------------------
# filling gaps and mapping onto the canonical joints


def _fill(track: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate missing points over time: ``(F, K, 2)`` positions, ``(K,)`` seen frames.

    Linear between valid frames, the nearest valid value held at the ends; keypoints
    never valid stay at 0 (``seen`` is 0 for them and the mapping does not use them).
    """
    num, k = track.shape[:2]
    valid = track[..., 2] > 0
    out = np.zeros((num, k, 2))
    t = np.arange(num, dtype=np.float64)
    for j in range(k):
        v = valid[:, j]
        if v.any():
            for c in range(2):
                out[:, j, c] = np.interp(t, t[v], track[v, j, c])
    return out, valid.sum(axis=0)


def _to_canonical(
    filled: np.ndarray,
    conf: np.ndarray,
    seen: np.ndarray,
    present: np.ndarray,
    lay: _Layout,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical ``positions (F, 22, 2)`` (image y down), ``confidence (F, 22)``,
    ``observed (22,)`` from filled source points ``(F, K, 2)`` and confidences ``(F, K)``.

    For each joint the first alternative of the recipe whose points are all seen in at
    least half of the frames with a person is used, else the first whose points are all
    seen at all; joints left without one are derived by ``_derive``.
    """
    num = filled.shape[0]
    n = len(CANONICAL_JOINTS)
    pos = np.zeros((num, n, 2))
    cf = np.zeros((num, n))
    observed = np.zeros(n, dtype=bool)
    have = np.zeros(n, dtype=bool)
    need = 0.5 * int(present.sum())
    for name, alternatives in lay.recipe.items():
        j = _J[name]
        observed[j] = True
        pick = next((a for a in alternatives if all(seen[i] >= need for i in a)), None)
        if pick is None:
            pick = next((a for a in alternatives if all(seen[i] > 0 for i in a)), None)
        if pick is None:
            continue
        idx = list(pick)
        pos[:, j] = filled[:, idx].mean(axis=1)
        cf[:, j] = conf[:, idx].min(axis=1)
        have[j] = True
    if not (have[_J["Hips"]] and have[_J["Neck"]]):
        raise MotionError(
            "the person's torso (hips and neck or shoulders) is never detected",
            kind="unusable",
        )
    _derive(pos, have)
    return pos, cf, observed


def _to_joint_centres(pos: np.ndarray) -> None:
    """Move the detector's hips, neck and head points to where the canonical skeleton has
    those joints (``HIPS_ABOVE_HIP_JOINTS`` etc.), in place; the head keeps its direction
    from the neck, so nods and tilts stay."""
    hips, neck = pos[:, _J["Hips"]].copy(), pos[:, _J["Neck"]].copy()
    torso = neck - hips
    pos[:, _J["Hips"]] = hips + HIPS_ABOVE_HIP_JOINTS * torso
    pos[:, _J["Neck"]] = neck + NECK_ABOVE_SHOULDERS * torso
    head = pos[:, _J["Head"]] - neck
    norm = np.linalg.norm(head, axis=-1, keepdims=True)
    direction = np.where(norm > 1e-9, head / np.maximum(norm, 1e-12), torso)
    direction /= np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-12)
    length = HEAD_FROM_NECK * np.linalg.norm(torso, axis=-1, keepdims=True)
    pos[:, _J["Head"]] = pos[:, _J["Neck"]] + length * direction


def _derive(pos: np.ndarray, have: np.ndarray) -> None:
    """Place the joints not taken from the input, in place. ``pos (F, 22, 2)``.

    Always derived: Spine and Chest on the Hips->Neck segment at ``SPINE_FRACTION`` and
    ``CHEST_FRACTION``; Shoulder_L/R at ``SHOULDER_FRACTION`` of Neck->UpperArm;
    joint_Root later by ``_place_root``. Never seen: a hip or shoulder mirrors the other
    one through Hips or Neck (or sits on it); a knee or elbow lies midway between its
    neighbours when the end point is seen, else hangs down the torso direction at the
    canonical proportions, as do a missing ankle, wrist or head; Toes sit on the ankle.
    Then Hips, Neck and Head move to the canonical joint centres (``_to_joint_centres``).
    """

    def p(name: str) -> np.ndarray:
        return pos[:, _J[name]]

    def put(name: str, value: np.ndarray) -> None:
        pos[:, _J[name]] = value
        have[_J[name]] = True

    hips, neck = p("Hips"), p("Neck")
    down = hips - neck  # (F, 2): one torso length, pointing from the neck to the hips
    if not have[_J["Head"]]:
        put("Head", neck - _HEAD_ABOVE_NECK * down)
    for side, other in (("L", "R"), ("R", "L")):
        for root, prox in ((hips, "UpperLeg"), (neck, "UpperArm")):
            if not have[_J[f"{prox}_{side}"]]:
                mirror = have[_J[f"{prox}_{other}"]]
                put(f"{prox}_{side}", 2 * root - p(f"{prox}_{other}") if mirror else root)
    for side in ("L", "R"):
        chains = (
            ("UpperLeg", "LowerLeg", "Foot", _THIGH, _SHIN),
            ("UpperArm", "LowerArm", "Hand", _UPPER_ARM, _FOREARM),
        )
        for prox, mid, end, first, second in chains:
            a, b, c = f"{prox}_{side}", f"{mid}_{side}", f"{end}_{side}"
            if not have[_J[b]]:
                if have[_J[c]]:
                    put(b, 0.5 * (p(a) + p(c)))
                else:
                    put(b, p(a) + first * down)
            if not have[_J[c]]:
                put(c, p(b) + second * down)
        if not have[_J[f"Toes_{side}"]]:
            put(f"Toes_{side}", p(f"Foot_{side}"))
    _to_joint_centres(pos)  # after mirroring through the detector's own mid-hip and neck
    put("Spine", hips + SPINE_FRACTION * (neck - hips))
    put("Chest", hips + CHEST_FRACTION * (neck - hips))
    for side in ("L", "R"):
        put(f"Shoulder_{side}", neck + SHOULDER_FRACTION * (p(f"UpperArm_{side}") - neck))


def _place_root(pos: np.ndarray) -> None:
    """joint_Root (y up): under the Hips, at the lower ankle's height. In place."""
    root = _J["joint_Root"]
    pos[:, root, 0] = pos[:, _J["Hips"], 0]
    pos[:, root, 1] = np.minimum(pos[:, _J["Foot_L"], 1], pos[:, _J["Foot_R"], 1])

"""Reading what pose detectors write: a zip or folder of per-frame OpenPose JSON files, or
one JSON document, into raw frames of people as ``(K, 3)`` arrays.

Every input is hostile until read: sizes are bounded before anything is decompressed or
parsed (``max_bytes``, ``max_frames``), zip paths and nested archives are refused, and
numbers must be numbers of sane size.
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
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from motion.errors import MotionError
from motion.keypoint_layouts import (
    BY_COUNT,
    Layout,
)

_MAX_COORD = 1e7

_NUMBER_TYPES = (int, float, type(None))
_NUMBER_TYPE_SET = frozenset(_NUMBER_TYPES)  # exact types: bool and str are not numbers here
_PERSON_KEYS = ("pose_keypoints_2d", "keypoints", "landmarks", "pose_landmarks")
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06", b"PK\x07\x08")
_ARCHIVE_SUFFIXES = (".zip", ".tar", ".gz", ".tgz", ".bz2", ".xz", ".7z", ".rar")


def read_source(data: Any, max_frames: int, max_bytes: int) -> tuple[list[Any], dict]:
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
                meta["image_size"] = check_image_size(doc["image_size"])
            elif doc.get("width") is not None and doc.get("height") is not None:
                meta["image_size"] = check_image_size((doc["width"], doc["height"]))
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


def parse_frame(frame: Any, index: int, lay: Layout | None) -> list[np.ndarray]:
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


def _parse_person(person: Any, where: str, lay: Layout | None) -> np.ndarray | None:
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


def _from_flat(values: list, where: str, lay: Layout | None) -> np.ndarray:
    n = len(values)
    if lay is not None:
        stride = n // lay.count if n % lay.count == 0 else 0
        if stride not in (2, 3, 4):
            raise MotionError(
                f"{where}: {n} numbers do not make {lay.count} points of layout {lay.name}"
            )
        return _to_array(values, stride, where)
    for stride in (3, 2, 4):
        if n % stride == 0 and n // stride in BY_COUNT:
            return _to_array(values, stride, where)
    if n % 2 and n % 3:
        raise MotionError(f"{where}: {n} numbers are not a list of (x, y[, score]) points")
    known = ", ".join(str(c) for c in sorted(BY_COUNT))
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


def clean_frames(frames: list[list[np.ndarray]], k: int, thr: float) -> list[np.ndarray]:
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


def _as_float(value: Any) -> float:
    """A JSON number as a float; an integer too large for one becomes inf (not an error)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def check_fps(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MotionError(f"fps must be a number, got {value!r:.80}")
    fps = _as_float(value)
    if not (math.isfinite(fps) and 0 < fps <= 1000):
        raise MotionError(f"fps must lie in (0, 1000], got {fps:g}")
    return fps


def check_image_size(value: Any) -> tuple[float, float]:
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


def looks_normalised(track: np.ndarray) -> bool:
    """True when every valid coordinate lies in [-0.5, 1.5] (detector gave 0..1 units)."""
    xy = track[..., :2][track[..., 2] > 0]
    return bool(xy.size) and bool(np.all((xy >= -0.5) & (xy <= 1.5)))

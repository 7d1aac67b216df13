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
  COCO layouts) are derived (:mod:`motion.keypoint_layouts`); their confidence is 0 and
  ``Keypoints2D.observed`` is False for them.

Reading is :mod:`motion.keypoint_files`, the layouts and their canonical joints
:mod:`motion.keypoint_layouts`; following one person and filling gaps are here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from motion import canonical as C
from motion.errors import MotionError
from motion.keypoint_files import (
    check_fps,
    check_image_size,
    clean_frames,
    looks_normalised,
    parse_frame,
    read_source,
)
from motion.keypoint_layouts import (
    detect_layout,
    place_root,
    resolve_layout,
    to_canonical,
)

DEFAULT_FPS = 30.0
DEFAULT_MAX_FRAMES = 20000
DEFAULT_MAX_BYTES = 64 * 1024 * 1024
DEFAULT_MIN_CONFIDENCE = 0.05

_SEED_FRAMES = 10
_MISSING_PENALTY = 0.5
_GATE = 0.5
_GATE_PER_GAP = 0.1
_GATE_MAX = 2.0
_MIN_OVERLAP = 0.3


@dataclass(frozen=True, eq=False)
class Keypoints2D:
    """One person's 2D keypoints on the canonical joints (``motion.canonical.JOINTS`` order).

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
        n = len(C.JOINTS)
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
    raw_frames, meta = read_source(data, max_frames, max_bytes)
    if len(raw_frames) > max_frames:
        raise MotionError(
            f"{len(raw_frames)} frames is over the limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    lay = resolve_layout(layout if layout is not None else meta.get("layout"))
    fps_value = check_fps(fps if fps is not None else meta.get("fps", DEFAULT_FPS))
    size = check_image_size(image_size) if image_size is not None else meta.get("image_size")
    frames = [parse_frame(frame, i, lay) for i, frame in enumerate(raw_frames)]
    lay = detect_layout(frames, lay)
    frames = clean_frames(frames, lay.count, thr)
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
    if size is None and looks_normalised(track):
        size = (1.0, 1.0)
    positions, confidence, observed = to_canonical(filled, track[..., 2], seen, present, lay)
    height = size[1] if size is not None else 0.0
    positions[..., 1] = height - positions[..., 1]
    place_root(positions)
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
    hips, neck = pos[:, C.INDEX["Hips"]], pos[:, C.INDEX["Neck"]]
    torso = np.linalg.norm(neck - hips, axis=-1)
    seen = (kp.confidence[:, C.INDEX["Hips"]] > 0) & (kp.confidence[:, C.INDEX["Neck"]] > 0)
    size = float(np.median(torso[seen] if seen.any() else torso))
    extent = float(np.ptp(pos[..., 1]))
    if not np.isfinite(size) or size <= 1e-9 * max(1.0, extent):
        raise MotionError("cannot normalise keypoints: the torso has no length", kind="unusable")
    return (pos - hips.mean(axis=0)) / size


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

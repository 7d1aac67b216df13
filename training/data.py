"""Datasets as canonical motions (22 joints, 30 fps), cached as compact ``.npz`` files.

- Bandai 1 and 2: style and content labels from the file names; a style name in
  both datasets is one style.
- CMU dance: salsa (60/61), Indian classical (94), modern (05) with a genre label.
- Dance with Melody: 3D marker positions fitted to the canonical skeleton with
  the IK, resampled to 30 fps, with the song's audio and where the dance sits in it.
- Unlabelled motion (``load_unlabelled_motion``): all of the above but Bandai, plus the
  CMU 31-joint takes and Xia's clips, without labels.

Clips carry a ``take`` id: splits are made by take, never by window, so no
validation frame is seen in training. The cache lives in ``$MOTION_CACHE_DIR``
(default ``cache/`` in the repo) and is rebuilt when the sources or
``CACHE_VERSION`` change.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import tarfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from motion.skeleton import Motion

REPO = Path(__file__).resolve().parent.parent
CACHE_VERSION = "2"


def data_dir() -> Path:
    return Path(os.environ.get("MOTION_DATA_DIR", REPO.parent / "shared" / "data")).resolve()


def cache_dir() -> Path:
    path = Path(os.environ.get("MOTION_CACHE_DIR", REPO / "cache"))
    path.mkdir(parents=True, exist_ok=True)
    return path


@dataclass
class Clip:
    """One take on the canonical skeleton at 30 fps, with its labels."""

    name: str
    dataset: str
    take: str  # unit of splitting
    lrot: np.ndarray  # (F, 22, 4)
    root: np.ndarray  # (F, 3) hips position
    style: str | None = None
    content: str | None = None
    genre: str | None = None
    extra: dict = field(default_factory=dict)

    @property
    def motion(self) -> Motion:
        return clip_motion(self)

    @property
    def num_frames(self) -> int:
        return int(self.lrot.shape[0])


def clip_motion(clip: Clip) -> Motion:
    """The clip as a canonical ``Motion`` (hips translation in ``lpos[:, 1]``)."""
    lpos = np.repeat(C.OFFSETS[None], clip.num_frames, axis=0)
    lpos[:, 0] = 0.0
    lpos[:, 1] = clip.root
    return Motion(C.SKELETON, C.FPS, clip.lrot, lpos)


def clip_from_motion(motion: Motion, **labels) -> Clip:
    """A clip from a canonical motion at 30 fps."""
    return Clip(
        lrot=motion.lrot.astype(np.float32), root=motion.lpos[:, 1].astype(np.float32), **labels
    )


# --------------------------------------------------------------------------- caching


def _fingerprint(paths: list[Path]) -> str:
    h = hashlib.sha256(CACHE_VERSION.encode())
    for p in sorted(paths):
        st = p.stat()
        h.update(f"{p.name}:{st.st_size}:{int(st.st_mtime)}".encode())
    return h.hexdigest()[:16]


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """``arrays`` compressed into ``path``, whole or not at all: written to a temporary file
    of this process's own (two processes may build one cache at once), then renamed."""
    path = Path(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def save_clips(path: Path, clips: list[Clip], fingerprint: str, half: bool = False) -> None:
    """``clips`` as a cache file (``read_clips`` reads it back). ``half``: rotations as
    float16, for a copy carried to a lent machine (half the bytes; quaternion components
    within 2.5e-4)."""
    meta = [
        {
            k: getattr(c, k)
            for k in ("name", "dataset", "take", "style", "content", "genre", "extra")
        }
        for c in clips
    ]
    save_npz(  # `make train-fast` builds the caches in two processes at once
        path,
        fingerprint=np.array(fingerprint),
        meta=np.array(json.dumps(meta)),
        lengths=np.array([c.num_frames for c in clips]),
        lrot=np.concatenate([c.lrot for c in clips]).astype(np.float16 if half else np.float32),
        root=np.concatenate([c.root for c in clips]).astype(np.float32),
    )


def _load_cache(path: Path, fingerprint: str | None) -> list[Clip] | None:
    """The clips of a cache file; ``None`` where it is missing or was built from other
    sources than ``fingerprint`` says (any, where ``None``)."""
    if not path.exists():
        return None
    with np.load(path) as z:
        if fingerprint is not None and str(z["fingerprint"]) != fingerprint:
            return None
        meta = json.loads(str(z["meta"]))
        bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
        lrot, root = z["lrot"], z["root"]
    if lrot.dtype == np.float16:
        lrot = lrot.astype(np.float32)
        lrot /= np.linalg.norm(lrot, axis=-1, keepdims=True)
    return [
        Clip(lrot=lrot[a:b], root=root[a:b], **m)
        for m, a, b in zip(meta, bounds[:-1], bounds[1:], strict=True)
    ]


def read_clips(path: Path) -> list[Clip]:
    """The clips of a cache file (``cache/bandai1.npz``, ...) whatever sources it was built
    from: a dataset carried to a machine without the data folder."""
    clips = _load_cache(Path(path), None)
    if clips is None:
        raise FileNotFoundError(path)
    return clips


def _cached(name: str, sources: list[Path], build) -> list[Clip]:
    if not sources:
        raise FileNotFoundError(
            f"no {name} data under {data_dir()}: set MOTION_DATA_DIR to the data folder"
        )
    return cached_by(name, _fingerprint(sources), build)


def cached_by(name: str, fingerprint: str, build) -> list[Clip]:
    """The clips of cache file ``name`` when it was built from ``fingerprint``, else
    ``build()``'s, saved there."""
    path = cache_dir() / f"{name}.npz"
    clips = _load_cache(path, fingerprint)
    if clips is None:
        clips = build()
        save_clips(path, clips, fingerprint)
    return clips


# --------------------------------------------------------------------------- Bandai


def _bandai_labels(stem: str) -> tuple[str, str, str, str]:
    dataset, content, style, take = stem.split("_")
    return dataset, content, style, take


def _to_clip(motion: Motion, **labels) -> Clip:
    rig = retarget.make_rig(motion.skeleton, motion)
    return clip_from_motion(retarget.to_canonical(motion, rig), **labels)


def load_bandai(root: Path | None = None, datasets: tuple[int, ...] = (1, 2)) -> list[Clip]:
    """Bandai dataset-1 (plain files) and dataset-2 (the subset archive), canonical, labelled."""
    root = (root or data_dir()) / "bandai"
    out: list[Clip] = []
    if 1 in datasets:
        files = sorted((root / "dataset-1").glob("*.bvh"))

        def build1() -> list[Clip]:
            clips = []
            for p in files:
                ds, content, style, take = _bandai_labels(p.stem)
                clips.append(
                    _to_clip(
                        bvh.load(p),
                        name=p.stem,
                        dataset=ds,
                        take=p.stem,
                        style=style,
                        content=content,
                    )
                )
            return clips

        out += _cached("bandai1", files, build1)
    if 2 in datasets:
        archive = root / "dataset-2" / "dataset-2-subset.tar.xz"

        def build2() -> list[Clip]:
            clips = []
            with tarfile.open(archive) as tar:
                for member in tar:
                    if not member.name.endswith(".bvh"):
                        continue
                    stem = Path(member.name).stem
                    ds, content, style, take = _bandai_labels(stem)
                    m = bvh.loads(tar.extractfile(member).read())
                    clips.append(
                        _to_clip(m, name=stem, dataset=ds, take=stem, style=style, content=content)
                    )
            return clips

        out += _cached("bandai2", [archive], build2)
    return out


def bandai_index(root: Path | None = None) -> list[dict]:
    """Rows of Bandai's ``index.csv`` (path, dataset, content, style, frames, fps)."""
    with open((root or data_dir()) / "bandai" / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


# --------------------------------------------------------------------------- CMU dance

CMU_DANCE_GENRES = {
    "60_01_scaled": "salsa", "61_01_scaled": "salsa", "60_09_scaled": "salsa",
    "61_09_scaled": "salsa", "94_01_indian_dance": "indian", "05_20": "modern",
    "05_11_pirouette": "modern",
}  # fmt: skip


def load_cmu_dance(root: Path | None = None) -> list[Clip]:
    """CMU dance takes (DAZ 43-joint and 3ds Max 31-joint layouts) with a genre label.

    cgspeed's synthetic first frame is dropped where the file has one.
    """
    root = root or data_dir()
    files = sorted((root / "cmu-dance-43").glob("*.bvh")) + sorted(
        (root / "cmu-dance-3dsmax").glob("*.bvh")
    )

    def build() -> list[Clip]:
        clips = []
        for p in files:
            m = bvh.load(p)
            if not p.stem.endswith("_scaled"):  # unmodified cgspeed files start with a T-pose
                m = m.slice(1)
            clips.append(
                _to_clip(
                    m,
                    name=p.stem,
                    dataset="cmu-dance",
                    take=p.stem,
                    genre=CMU_DANCE_GENRES.get(p.stem),
                )
            )
        return clips

    return _cached("cmu_dance", files, build)


# --------------------------------------------------------------------------- CMU 31 and Xia


def load_bvh_folder(folder: str, root: Path | None = None) -> list[Clip]:
    """Every BVH of a data folder (``cmu-31``, ``xia``), canonical, named by file, no labels."""
    files = sorted(((root or data_dir()) / folder).glob("*.bvh"))

    def build() -> list[Clip]:
        return [_to_clip(bvh.load(p), name=p.stem, dataset=folder, take=p.stem) for p in files]

    return _cached(folder.replace("-", "_"), files, build)


def load_unlabelled_motion(root: Path | None = None) -> list[Clip]:
    """Every motion in the data but Bandai's, labels dropped: CMU 31-joint takes, Xia's
    styled clips, CMU dance and Dance with Melody (about 54k frames at 30 fps), each take
    once (CMU 05_20 is in both CMU folders)."""
    clips = (
        load_bvh_folder("cmu-31", root)
        + load_bvh_folder("xia", root)
        + load_cmu_dance(root)
        + load_dance_with_melody(root)
    )
    firsts = {}
    for c in clips:
        firsts.setdefault(c.take, replace(c, style=None, content=None, genre=None))
    return list(firsts.values())


# --------------------------------------------------------------------------- splits


def split_by_take(
    clips: list[Clip], val_fraction: float = 0.15, seed: int = 0, stratify: str | None = "style"
) -> tuple[list[Clip], list[Clip]]:
    """Train/validation split by take; with ``stratify``, each label value keeps its share."""
    rng = np.random.default_rng(seed)
    groups: dict = {}
    for c in clips:
        groups.setdefault(getattr(c, stratify) if stratify else None, []).append(c)
    train, val = [], []
    for key in sorted(groups, key=str):
        items = sorted(groups[key], key=lambda c: c.take)
        takes = sorted({c.take for c in items})
        n_val = int(round(len(takes) * val_fraction))
        chosen = set(rng.choice(takes, size=n_val, replace=False)) if n_val else set()
        for c in items:
            (val if c.take in chosen else train).append(c)
    return train, val


# --------------------------------------------------------------------------- Dance with Melody

DWM_FPS = 25.0
DWM_GENRES = {"C": "cha-cha", "R": "rumba", "T": "tango", "W": "waltz"}


def dwm_canonical_positions(points: np.ndarray) -> np.ndarray:
    """Canonical joint positions ``(F, 22, 3)`` from Dance-with-Melody markers ``(F, 23, 3)``.

    The 23 points are marker-like (data README: 0/1 head, 2 pelvis top, 3-6 right arm
    to hand, 7-11 right hip, knee, ankle, heel, toe, 12-15 left arm, 16-20 left leg,
    21/22 hand direction). Joints with no marker are placed at the fractions the
    canonical skeleton has (chest at 0.35 from spine to neck, clavicle start halfway
    from the neck base to the shoulder).
    """
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros(p.shape[:-2] + (len(C.JOINTS), 3))
    hip_mid = 0.5 * (p[..., 7, :] + p[..., 16, :])
    neck_base = 0.5 * (p[..., 3, :] + p[..., 12, :])
    head = 0.5 * (p[..., 0, :] + p[..., 1, :])
    put = {
        "Hips": hip_mid + 0.12 * (p[..., 2, :] - hip_mid),
        "Spine": p[..., 2, :],
        "Chest": p[..., 2, :] + 0.35 * (neck_base - p[..., 2, :]),
        "Neck": neck_base + 0.2 * (head - neck_base),
        "Head": head,
        "UpperArm_L": p[..., 12, :], "LowerArm_L": p[..., 13, :], "Hand_L": p[..., 15, :],
        "UpperArm_R": p[..., 3, :], "LowerArm_R": p[..., 4, :], "Hand_R": p[..., 6, :],
        "UpperLeg_L": p[..., 16, :], "LowerLeg_L": p[..., 17, :], "Foot_L": p[..., 18, :],
        "Toes_L": p[..., 20, :],
        "UpperLeg_R": p[..., 7, :], "LowerLeg_R": p[..., 8, :], "Foot_R": p[..., 9, :],
        "Toes_R": p[..., 11, :],
    }  # fmt: skip
    put["Shoulder_L"] = neck_base + 0.5 * (p[..., 12, :] - neck_base)
    put["Shoulder_R"] = neck_base + 0.5 * (p[..., 3, :] - neck_base)
    for name, value in put.items():
        out[..., C.INDEX[name], :] = value
    # joint_Root stays at the origin (zeros): the Hips carry the dancer's path, which a Clip
    # keeps; a root following the hips on the floor had taken the path, and a Clip drops it
    return out


def read_dwm_folder(folder: Path) -> tuple[np.ndarray, dict]:
    """Marker positions ``(F, 23, 3)`` (``skeletons + center``, the global path) and config."""
    with open(folder / "skeletons.json") as f:
        doc = json.load(f)
    with open(folder / "config.json") as f:
        config = json.load(f)
    points = np.asarray(doc["skeletons"], dtype=np.float64) + np.asarray(doc["center"])[:, None]
    return points, config


def load_dance_with_melody(root: Path | None = None) -> list[Clip]:
    """Dance-with-Melody dances on the canonical skeleton at 30 fps, labelled by genre.

    Marker positions are fitted with ``motion.fit.fit_positions`` (bone lengths exact,
    pelvis and chest from several markers), the floor is put at the feet's ground
    level, and the clip remembers where it sits in its song: ``extra["audio"]`` (path
    relative to the data folder) and ``extra["audio_offset_s"]`` (``start_position /
    25`` as ``config.json`` gives it; see issue 5 for whether that alignment holds).
    """
    from motion import contacts, fit, kinematics

    root = (root or data_dir()) / "dance-with-melody"
    folders = sorted(p for p in root.glob("DANCE_*") if (p / "skeletons.json").exists())

    def build() -> list[Clip]:
        clips = []
        for folder in folders:
            points, config = read_dwm_folder(folder)
            target = dwm_canonical_positions(points)
            motion = fit.fit_positions(target, C.SKELETON, fps=DWM_FPS)
            gpos = kinematics.global_positions(motion)
            toes = [C.INDEX["Toes_L"], C.INDEX["Toes_R"]]
            floor = float(np.min(contacts.ground_heights(gpos, toes)))  # toes on y = 0
            lpos = motion.lpos.copy()
            lpos[:, 1, 1] -= floor
            motion = kinematics.resample(motion.replace(lpos=lpos), C.FPS)
            genre = DWM_GENRES[folder.name.split("_")[1]]
            clips.append(
                clip_from_motion(
                    motion,
                    name=folder.name,
                    dataset="dance-with-melody",
                    take=folder.name,
                    genre=genre,
                    extra={
                        "audio": f"dance-with-melody/{folder.name}/audio.mp3",
                        "audio_offset_s": config["start_position"] / DWM_FPS,
                        "config": config,
                        "source_frames": int(points.shape[0]),
                    },
                )
            )
        return clips

    return _cached("dance_with_melody", [f / "skeletons.json" for f in folders], build)


def clip_audio(clip: Clip, root: Path | None = None) -> tuple[np.ndarray, int]:
    """The part of a dance clip's song that its motion covers, as mono samples and rate."""
    from motion import audio_decode

    samples, sr = audio_decode.decode((root or data_dir()) / clip.extra["audio"])
    start = int(round(clip.extra["audio_offset_s"] * sr))
    stop = start + int(round(clip.num_frames / C.FPS * sr))
    return samples[start:stop], sr

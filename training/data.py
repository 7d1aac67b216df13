"""Datasets as canonical motions (22 joints, 30 fps), cached as compact ``.npz`` files.

- Bandai 1 and 2: style and content labels from the file names; a style name in
  both datasets is one style.
- CMU dance: salsa (60/61), Indian classical (94), modern (05) with a genre label.
- Dance with Melody: 3D marker positions fitted to the canonical skeleton with
  the IK, resampled to 30 fps, with the song's audio and where the dance sits in it.

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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from motion.skeleton import Motion

REPO = Path(__file__).resolve().parent.parent
CACHE_VERSION = "1"


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


def _save_cache(path: Path, clips: list[Clip], fingerprint: str) -> None:
    meta = [
        {
            k: getattr(c, k)
            for k in ("name", "dataset", "take", "style", "content", "genre", "extra")
        }
        for c in clips
    ]
    lengths = np.array([c.num_frames for c in clips])
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(
        tmp,
        fingerprint=np.array(fingerprint),
        meta=np.array(json.dumps(meta)),
        lengths=lengths,
        lrot=np.concatenate([c.lrot for c in clips]).astype(np.float32),
        root=np.concatenate([c.root for c in clips]).astype(np.float32),
    )
    os.replace(tmp, path)


def _load_cache(path: Path, fingerprint: str) -> list[Clip] | None:
    if not path.exists():
        return None
    with np.load(path) as z:
        if str(z["fingerprint"]) != fingerprint:
            return None
        meta = json.loads(str(z["meta"]))
        bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
        lrot, root = z["lrot"], z["root"]
    return [
        Clip(lrot=lrot[a:b], root=root[a:b], **m)
        for m, a, b in zip(meta, bounds[:-1], bounds[1:], strict=True)
    ]


def _cached(name: str, sources: list[Path], build) -> list[Clip]:
    fp = _fingerprint(sources)
    path = cache_dir() / f"{name}.npz"
    clips = _load_cache(path, fp)
    if clips is None:
        clips = build()
        _save_cache(path, clips, fp)
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

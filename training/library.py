"""A studio's motion library: a folder of clips on any humanoid rig and ``labels.csv``.

``labels.csv`` has one row per clip, a header and at least the columns ``file`` (path
relative to the folder: ``.bvh``, ``.glb`` or ``.gltf``), ``style`` and ``content`` (the
action performed). Optional columns:

- ``take``: the take's id, the unit that splits never cut (default: ``file`` without its
  suffix); unique in the library;
- ``actor``: who performed it (default: unknown, one actor);
- ``mirror_ok``: whether the clip performed with left and right swapped is still a take of
  its style (``yes``/``no``, default yes); the mirror's content swaps the words ``left``
  and ``right``;
- ``held_out``: whether the take is kept out of training, for validation and evaluation
  (``yes``/``no``); by default one take in ten (a hash of its id) of each style, content
  and actor that has at least :data:`HELD_OUT_GROUP` takes, so every pair stays trainable.

No label is read from a file name. :func:`read_labels` reads and checks the table,
:func:`read_library` the clips, on the canonical skeleton at 30 fps (``training.data.Clip``
with ``extra`` holding ``file``, ``actor``, ``mirror_ok`` and ``held_out``), cached under
``$MOTION_CACHE_DIR`` by the library's content hash.
"""

from __future__ import annotations

import csv
import hashlib
import os
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from motion import bvh, gltf, retarget
from motion.errors import MotionError
from motion.skeleton import Motion
from training import data as D

LABELS = "labels.csv"
REQUIRED_COLUMNS = ("file", "style", "content")
OPTIONAL_COLUMNS = ("take", "actor", "mirror_ok", "held_out")
READERS = {".bvh": "bvh", ".glb": "gltf", ".gltf": "gltf"}
HELD_OUT_GROUP = 4  # takes of one style, content and actor before one in ten is held out
HELD_OUT_ONE_IN = 10
_YES = {"yes", "y", "true", "1"}
_NO = {"no", "n", "false", "0"}


class LibraryError(ValueError):
    """A library that cannot be trained on; ``problems`` names each thing wrong with it."""

    def __init__(self, root: Path, problems: list[str]) -> None:
        self.root = Path(root)
        self.problems = list(problems)
        super().__init__(f"library {root}: " + "; ".join(problems))


@dataclass(frozen=True)
class Row:
    """One clip's labels (``line``: its line in ``labels.csv``)."""

    file: str
    style: str
    content: str
    take: str
    actor: str
    mirror_ok: bool
    held_out: bool
    line: int


@dataclass
class Library:
    """A library folder and its labelled rows."""

    root: Path
    rows: list[Row]

    @property
    def name(self) -> str:
        return self.root.resolve().name

    def path(self, row: Row) -> Path:
        return self.root / row.file

    def content_hash(self) -> str:
        """SHA-256 of ``labels.csv`` and every clip's bytes, in the table's order: the same
        hash is the same training data."""
        h = hashlib.sha256((self.root / LABELS).read_bytes())
        for row in self.rows:
            h.update(row.file.encode() + b"\0")
            with open(self.path(row), "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
        return h.hexdigest()


def _flag(value: str, column: str, line: int, default: bool, problems: list[str]) -> bool:
    v = value.strip().lower()
    if not v:
        return default
    if v in _YES:
        return True
    if v in _NO:
        return False
    problems.append(f"labels.csv line {line}: {column} is {value!r}, not yes or no")
    return default


def held_out_by_rule(take: str) -> bool:
    """One take id in :data:`HELD_OUT_ONE_IN`, by a hash of it (stable across machines)."""
    return zlib.crc32(take.encode()) % HELD_OUT_ONE_IN == 0


def read_labels(root: Path) -> tuple[Library, list[str]]:
    """The library at ``root`` and the problems of its table: columns, empty labels, files
    missing, outside the folder or of a format not read, duplicate files or takes. Files
    are not opened."""
    root = Path(root)
    problems: list[str] = []
    labels = root / LABELS
    if not root.is_dir():
        return Library(root, []), [f"{root} is not a folder"]
    if not labels.is_file():
        return Library(root, []), [f"no {LABELS} in {root}"]
    with open(labels, newline="", encoding="utf-8-sig") as f:
        reader = csv.DictReader(f)
        columns = [c.strip() for c in reader.fieldnames or []]
        missing = [c for c in REQUIRED_COLUMNS if c not in columns]
        if missing:
            return Library(root, []), [f"{LABELS} lacks the column(s) {', '.join(missing)}"]
        unknown = [c for c in columns if c not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS]
        if unknown:
            problems.append(
                f"{LABELS} has unknown column(s) {', '.join(unknown)} "
                f"(known: {', '.join(REQUIRED_COLUMNS + OPTIONAL_COLUMNS)})"
            )
        raw = [({k.strip(): (v or "").strip() for k, v in r.items() if k}, reader.line_num)
               for r in reader]  # fmt: skip
    rows, given_held_out = [], []
    for r, line in raw:
        file = r["file"].replace("\\", "/")
        empty = [c for c in REQUIRED_COLUMNS if not r.get(c)]
        if empty:
            problems.append(f"{LABELS} line {line}: empty {', '.join(empty)}")
            continue
        path = root / file
        # lexically inside (a link may point anywhere: a studio's choice)
        if Path(file).is_absolute() or ".." in Path(os.path.normpath(file)).parts:
            problems.append(f"{LABELS} line {line}: {file} lies outside the library folder")
            continue
        if path.suffix.lower() not in READERS:
            why = (
                "FBX is not read by training yet: export BVH or GLB"
                if path.suffix.lower() == ".fbx"
                else f"not a clip format read here ({', '.join(READERS)})"
            )
            problems.append(f"{LABELS} line {line}: {file}: {why}")
            continue
        if not path.is_file():
            problems.append(f"{LABELS} line {line}: {file} does not exist")
            continue
        take = r.get("take") or str(Path(file).with_suffix("")).replace("\\", "/")
        mirror_ok = _flag(r.get("mirror_ok", ""), "mirror_ok", line, True, problems)
        held_out = r.get("held_out", "")
        given_held_out.append(bool(held_out))
        rows.append(
            Row(
                file=file,
                style=r["style"],
                content=r["content"],
                take=take,
                actor=r.get("actor", ""),
                mirror_ok=mirror_ok,
                held_out=_flag(held_out, "held_out", line, False, problems),
                line=line,
            )
        )
    for what, values in (("file", [r.file for r in rows]), ("take", [r.take for r in rows])):
        for value, n in Counter(values).items():
            if n > 1:
                problems.append(f"{LABELS}: {what} {value} appears on {n} rows")
    if rows and not any(given_held_out):
        rows = _held_out_by_default(rows)
    return Library(root, rows), problems


def _held_out_by_default(rows: list[Row]) -> list[Row]:
    from dataclasses import replace

    group = Counter((r.style, r.content, r.actor) for r in rows)
    return [
        replace(
            r,
            held_out=group[r.style, r.content, r.actor] >= HELD_OUT_GROUP
            and held_out_by_rule(r.take),
        )
        for r in rows
    ]


def load_motion(path: Path) -> Motion:
    """A clip file's motion as its own rig plays it (BVH or glTF by the file's bytes);
    ``MotionError`` where it cannot be read."""
    data = Path(path).read_bytes()
    if gltf.is_gltf(data):
        return gltf.loads(data)
    return bvh.loads(data)


def canonical_clip(library: Library, row: Row, motion: Motion) -> tuple[D.Clip, retarget.Rig]:
    """``row``'s clip on the canonical skeleton at 30 fps with its labels, and its rig
    (``MotionError`` where the rig cannot be mapped)."""
    rig = retarget.make_rig(motion.skeleton, motion)
    canon = retarget.to_canonical(motion, rig)
    clip = D.clip_from_motion(
        canon,
        name=row.take,
        dataset=library.name,
        take=row.take,
        style=row.style,
        content=row.content,
        extra={
            "file": row.file,
            "actor": row.actor,
            "mirror_ok": row.mirror_ok,
            "held_out": row.held_out,
        },
    )
    return clip, rig


def convert(library: Library) -> tuple[list[D.Clip | None], list[retarget.Rig | str]]:
    """Every row's canonical clip and rig, or ``None`` and the problem where a file cannot
    be read or its rig mapped."""
    clips: list[D.Clip | None] = []
    rigs: list[retarget.Rig | str] = []
    for row in library.rows:
        try:
            clip, rig = canonical_clip(library, row, load_motion(library.path(row)))
        except MotionError as e:
            clips.append(None)
            rigs.append(f"{row.file}: {e.message}")
            continue
        clips.append(clip)
        rigs.append(rig)
    return clips, rigs


def read_library(root: Path) -> list[D.Clip]:
    """The library's clips in the table's order, canonical and labelled (cached by content
    hash); :class:`LibraryError` naming every problem of the table or a file."""
    library, problems = read_labels(root)
    if problems:
        raise LibraryError(library.root, problems)
    return clips_of(library)


def clips_of(library: Library, converted: list[D.Clip | None] | None = None) -> list[D.Clip]:
    """The library's clips, from the cache when its content hash matches, else converted
    (``converted``: already, by :func:`convert`) and cached."""

    def build() -> list[D.Clip]:
        clips = converted
        if clips is None:
            clips, rigs = convert(library)
            failed = [r for r in rigs if isinstance(r, str)]
            if failed:
                raise LibraryError(library.root, failed)
        return [c for c in clips if c is not None]

    return D.cached_by(
        f"library-{library.name}", f"{D.CACHE_VERSION}:{library.content_hash()}", build
    )

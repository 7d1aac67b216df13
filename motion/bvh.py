"""BVH read/write: ``load``/``loads`` to a :class:`~motion.skeleton.Motion`, ``save``/``dumps`` back.

Reads any channel order and any subset of the six channels on any joint
(3 on most CMU joints, 6 on every Bandai joint, mixed orders in one file),
End Sites, tabs, CRLF/LF/CR line endings and names with spaces (3ds Max
``Bip01 L Thigh``) or colons (Mixamo ``mixamorig:Hips``). Position channels
replace the joint's OFFSET (what Bandai, CMU and most tools mean).
Writing keeps names, offsets, End Sites, channel layout and frame time, so
``loads(dumps(m))`` reproduces ``m`` to print precision. Malformed input
raises :class:`~motion.errors.MotionError` naming the line and the problem.
"""

from __future__ import annotations

import io
import math
import os
import re
import warnings

import numpy as np

from motion import rotations
from motion.errors import MotionError
from motion.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Motion, Skeleton

_VALID_CHANNELS = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}
_FRAMES_RE = re.compile(r"^frames\s*:?\s*(\S+)$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^frame\s+time\s*:?\s*(\S+)$", re.IGNORECASE)
_MAX_ABS_VALUE = 1e9  # offsets and channel values beyond this are damage, not motion
_MIN_FRAME_TIME = 1e-4  # 10,000 fps: no capture system records faster
_MAX_DEPTH = 256  # real rigs nest < 100 deep; deeper would overflow recursive writers


def load(path: str | os.PathLike) -> Motion:
    """Read a BVH file."""
    with open(path, "rb") as f:
        return loads(f.read())


def loads(data: str | bytes) -> Motion:
    """Parse BVH text (``str`` or ``bytes``)."""
    if isinstance(data, bytes | bytearray | memoryview):
        data = _decode(bytes(data))
    if "\x00" in data:
        raise MotionError("not a BVH file: it contains binary data")
    lines = data.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    skeleton, motion_line = _parse_hierarchy(lines)
    fps, values = _parse_motion(lines, motion_line, skeleton)
    return _to_motion(skeleton, fps, values)


def _decode(raw: bytes) -> str:
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


class _Lines:
    """Non-empty stripped lines with their 1-based numbers."""

    def __init__(self, lines: list[str], start: int = 0) -> None:
        self.lines = lines
        self.i = start

    def next(self, what: str) -> tuple[int, str]:
        while self.i < len(self.lines):
            text = self.lines[self.i].strip()
            self.i += 1
            if text:
                return self.i, text
        raise MotionError(f"unexpected end of file: expected {what}", line=len(self.lines))


def _parse_floats(tokens: list[str], n: int, line: int, what: str) -> list[float]:
    if len(tokens) != n:
        raise MotionError(f"line {line}: {what} needs {n} numbers, found {len(tokens)}", line=line)
    try:
        vals = [float(t) for t in tokens]
    except ValueError:
        raise MotionError(
            f"line {line}: {what} has a value that is not a number", line=line
        ) from None
    if not all(math.isfinite(v) for v in vals):
        raise MotionError(f"line {line}: {what} is not finite", line=line)
    if any(abs(v) > _MAX_ABS_VALUE for v in vals):
        raise MotionError(f"line {line}: {what} has an absurdly large value", line=line)
    return vals


def _parse_hierarchy(lines: list[str]) -> tuple[Skeleton, int]:
    src = _Lines(lines)
    n, text = src.next("HIERARCHY")
    if text.upper() != "HIERARCHY":
        raise MotionError(
            f"line {n}: not a BVH file: expected 'HIERARCHY', found {text[:40]!r}", line=n
        )
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, list[tuple[float, float, float]]] = {}
    stack: list[int | None] = []  # joint index per open brace; None for an End Site
    pending: tuple[str, int | None] | None = None  # ("joint"|"end", parent) awaiting '{'
    n, text = src.next("ROOT")
    head = text.split(None, 1)
    if head[0].upper() != "ROOT" or len(head) < 2:
        raise MotionError(f"line {n}: expected 'ROOT <name>', found {text[:40]!r}", line=n)
    names.append(head[1].strip())
    seen = {names[0]}  # a set beside the list: 10,000 joints must not cost 10,000^2 compares
    parents.append(-1)
    offsets.append([0.0, 0.0, 0.0])
    channels.append(())
    pending = ("joint", len(names) - 1)
    while True:
        n, text = src.next("'}' closing the hierarchy")
        tokens = text.split()
        key = tokens[0].upper()
        if pending is not None:
            if text != "{":
                raise MotionError(f"line {n}: expected '{{', found {text[:40]!r}", line=n)
            stack.append(pending[1] if pending[0] == "joint" else None)
            pending = None
            if len(stack) > _MAX_DEPTH:
                raise MotionError(f"line {n}: joints nested more than {_MAX_DEPTH} deep", line=n)
            continue
        if not stack:
            if key == "MOTION":
                break
            if key == "ROOT":
                raise MotionError(
                    f"line {n}: files with more than one ROOT are not supported", line=n
                )
            raise MotionError(f"line {n}: expected 'MOTION', found {text[:40]!r}", line=n)
        top = stack[-1]
        if key == "}":
            stack.pop()
        elif key == "OFFSET":
            vals = _parse_floats(tokens[1:], 3, n, "OFFSET")
            if top is None:
                parent = _end_site_parent(stack)
                end_sites.setdefault(parent, []).append(tuple(vals))
            else:
                offsets[top] = vals
        elif key == "CHANNELS":
            if top is None:
                raise MotionError(f"line {n}: an End Site cannot have channels", line=n)
            try:
                count = int(tokens[1])
            except (IndexError, ValueError):
                raise MotionError(f"line {n}: CHANNELS needs a count", line=n) from None
            names_ = tokens[2:]
            if count != len(names_):
                raise MotionError(
                    f"line {n}: CHANNELS says {tokens[1]} but lists {len(names_)} channels", line=n
                )
            if not 0 <= count <= 6:
                raise MotionError(f"line {n}: CHANNELS lists {count}; at most 6", line=n)
            chans = []
            for c in names_:
                if c.lower() not in _VALID_CHANNELS:
                    raise MotionError(f"line {n}: unknown channel {c!r}", line=n)
                chans.append(_VALID_CHANNELS[c.lower()])
            if len(set(chans)) != len(chans):
                raise MotionError(f"line {n}: a channel is listed twice", line=n)
            channels[top] = tuple(chans)
        elif key == "JOINT":
            if top is None:
                raise MotionError(f"line {n}: an End Site cannot have joints", line=n)
            name = text.split(None, 1)[1].strip() if len(tokens) > 1 else ""
            if not name:
                raise MotionError(f"line {n}: JOINT needs a name", line=n)
            if name in seen:
                raise MotionError(f"line {n}: joint name {name!r} is used twice", line=n)
            seen.add(name)
            names.append(name)
            parents.append(top)
            offsets.append([0.0, 0.0, 0.0])
            channels.append(())
            pending = ("joint", len(names) - 1)
        elif key == "END":
            if top is None:
                raise MotionError(f"line {n}: an End Site cannot have children", line=n)
            pending = ("end", None)
        else:
            raise MotionError(f"line {n}: unexpected {text[:40]!r} in the hierarchy", line=n)
        if len(names) > 10_000:
            raise MotionError(f"line {n}: more than 10000 joints", line=n)
    # Depth-first file order guarantees parents[j] < j.
    skeleton = Skeleton(
        names=tuple(names),
        parents=np.array(parents),
        offsets=np.array(offsets),
        channels=tuple(channels),
        end_sites={k: tuple(v) for k, v in end_sites.items()},
    )
    return skeleton, src.i


def _end_site_parent(stack: list[int | None]) -> int:
    for item in reversed(stack):
        if item is not None:
            return item
    raise MotionError("End Site outside a joint")


def _parse_motion(lines: list[str], start: int, skeleton: Skeleton) -> tuple[float, np.ndarray]:
    src = _Lines(lines, start)
    n, text = src.next("'Frames:'")
    m = _FRAMES_RE.match(text)
    if not m:
        raise MotionError(f"line {n}: expected 'Frames: <count>', found {text[:40]!r}", line=n)
    try:
        declared = int(m.group(1))
    except ValueError:
        raise MotionError(
            f"line {n}: frame count {m.group(1)!r} is not a whole number", line=n
        ) from None
    if declared < 0:
        raise MotionError(f"line {n}: negative frame count", line=n)
    n, text = src.next("'Frame Time:'")
    m = _FRAME_TIME_RE.match(text)
    if not m:
        raise MotionError(
            f"line {n}: expected 'Frame Time: <seconds>', found {text[:40]!r}", line=n
        )
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise MotionError(f"line {n}: frame time {m.group(1)!r} is not a number", line=n) from None
    if not math.isfinite(frame_time) or not _MIN_FRAME_TIME <= frame_time <= 10:
        raise MotionError(f"line {n}: frame time {frame_time} s is not usable", line=n)
    num_channels = sum(len(c) for c in skeleton.channels)
    first = src.i
    rows = lines[first:]
    counts = [len(r.split()) for r in rows]
    while counts and counts[-1] == 0:  # trailing blank lines
        counts.pop()
    bad = [i for i, c in enumerate(counts) if c != num_channels]
    if bad:
        i = bad[0]
        raise MotionError(
            f"line {first + i + 1}: frame has {counts[i]} values, the hierarchy needs {num_channels}",
            line=first + i + 1,
        )
    frames = len(counts)
    if frames == 0:
        raise MotionError(f"line {n}: the file has no frames", line=n)
    if frames < declared:
        raise MotionError(
            f"line {first + frames}: file ends after {frames} frames, header says {declared}",
            line=first + frames,
        )
    values = None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a non-number makes fromstring warn and stop early
        try:
            values = np.fromstring(" ".join(rows[:frames]), dtype=np.float64, sep=" ")
        except (DeprecationWarning, ValueError):
            values = None
    if values is None or values.size != frames * num_channels:
        for i, r in enumerate(rows[:frames]):
            try:
                [float(t) for t in r.split()]
            except ValueError:
                raise MotionError(
                    f"line {first + i + 1}: a value is not a number", line=first + i + 1
                ) from None
        raise MotionError(
            f"line {first + 1}: the frames could not be read as numbers", line=first + 1
        )
    values = values.reshape(frames, num_channels)
    if not np.isfinite(values).all():
        i = int(np.nonzero(~np.isfinite(values).all(axis=1))[0][0])
        raise MotionError(f"line {first + i + 1}: a value is not finite", line=first + i + 1)
    if np.abs(values).max(initial=0.0) > _MAX_ABS_VALUE:
        i = int(np.nonzero((np.abs(values) > _MAX_ABS_VALUE).any(axis=1))[0][0])
        raise MotionError(f"line {first + i + 1}: a value is absurdly large", line=first + i + 1)
    return 1.0 / frame_time, values


def _to_motion(skeleton: Skeleton, fps: float, values: np.ndarray) -> Motion:
    frames = values.shape[0]
    lpos = np.repeat(skeleton.offsets[None], frames, axis=0)
    euler = np.zeros((frames, skeleton.num_joints, 3))
    col = 0
    for j, chans in enumerate(skeleton.channels):
        order = skeleton.rotation_order(j)
        for c in chans:
            if c in POSITION_CHANNELS:
                lpos[:, j, "XYZ".index(c[0])] = values[:, col]
            else:
                euler[:, j, order.index(c[0])] = values[:, col]
            col += 1
    lrot = np.empty((frames, skeleton.num_joints, 4))
    orders: dict[str, list[int]] = {}
    for j in range(skeleton.num_joints):
        orders.setdefault(skeleton.rotation_order(j), []).append(j)
    for order, joints in orders.items():  # one scipy call per Euler order, not per joint
        lrot[:, joints] = rotations.from_euler(euler[:, joints], order)
    return Motion(skeleton, fps, lrot, lpos)


def _fmt(v: np.ndarray | list[float]) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def dumps(motion: Motion) -> str:
    """BVH text of ``motion`` on its skeleton's own channel layout."""
    sk = motion.skeleton
    out = io.StringIO()
    out.write("HIERARCHY\n")
    children = [sk.children(j) for j in range(sk.num_joints)]

    def write_joint(j: int, depth: int) -> None:
        ind = "\t" * depth
        kind = "ROOT" if j == 0 else "JOINT"
        out.write(f"{ind}{kind} {sk.names[j]}\n{ind}{{\n")
        out.write(f"{ind}\tOFFSET {_fmt(sk.offsets[j])}\n")
        chans = sk.channels[j]
        out.write(f"{ind}\tCHANNELS {len(chans)}{' ' if chans else ''}{' '.join(chans)}\n")
        for c in children[j]:
            write_joint(c, depth + 1)
        for off in sk.end_sites.get(j, ()):
            out.write(f"{ind}\tEnd Site\n{ind}\t{{\n{ind}\t\tOFFSET {_fmt(off)}\n{ind}\t}}\n")
        out.write(f"{ind}}}\n")

    write_joint(0, 0)
    out.write(f"MOTION\nFrames: {motion.num_frames}\nFrame Time: {1.0 / motion.fps:.7f}\n")
    out.write(_motion_block(motion))
    return out.getvalue()


def _motion_block(motion: Motion) -> str:
    sk = motion.skeleton
    cols = []
    for j, chans in enumerate(sk.channels):
        order = sk.rotation_order(j)
        euler = None
        if any(c in ROTATION_CHANNELS for c in chans):
            euler = rotations.to_euler(motion.lrot[:, j], order)
            euler = np.rad2deg(np.unwrap(np.deg2rad(euler), axis=0))  # no 360-degree jumps
        for c in chans:
            if c in POSITION_CHANNELS:
                cols.append(motion.lpos[:, j, "XYZ".index(c[0])])
            else:
                cols.append(euler[:, order.index(c[0])])
    if not cols:
        return "\n" * motion.num_frames
    data = np.stack(cols, axis=1)
    buf = io.StringIO()
    np.savetxt(buf, data, fmt="%.6f", delimiter=" ")
    return buf.getvalue()


def save(motion: Motion, path: str | os.PathLike) -> None:
    """Write ``motion`` as a BVH file."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(dumps(motion))

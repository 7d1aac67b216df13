"""BVH read/write: ``load``/``loads`` to a :class:`~motion.skeleton.Motion`, ``save``/``dumps`` back.

Reads any channel order and any subset of the six channels on any joint
(3 on most CMU joints, 6 on every Bandai joint, mixed orders in one file),
End Sites, tabs, CRLF/LF/CR line endings and names with spaces (3ds Max
``Bip01 L Thigh``) or colons (Mixamo ``mixamorig:Hips``). Position channels
replace the joint's OFFSET (what Bandai, CMU and most tools mean).
Writing keeps names, offsets, End Sites, channel layout and frame time, so
``loads(dumps(m))`` reproduces ``m`` to print precision. Malformed input
raises :class:`~motion.errors.MotionError` naming the line and the problem.
The numbers of the motion block are read and written by compiled loops
(``motion.bvh_kernels``), the service's hottest text code.
"""

from __future__ import annotations

import io
import math
import os
import re
import warnings

import numpy as np

from motion import bvh_kernels, kernels, rotations
from motion.errors import MotionError
from motion.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Motion, Skeleton

_VALID_CHANNELS = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}
_FRAMES_RE = re.compile(r"^frames\s*:?\s*(\S+)$", re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r"^frame\s+time\s*:?\s*(\S+)$", re.IGNORECASE)
MAX_ABS_VALUE = 1e9  # offsets and channel values beyond this are damage, not motion
_MIN_FRAME_TIME = 1e-4  # 10,000 fps: no capture system records faster
_MAX_DEPTH = 256  # real rigs nest < 100 deep; deeper would overflow recursive writers


def load(path: str | os.PathLike) -> Motion:
    """Read a BVH file."""
    with open(path, "rb") as f:
        return loads(f.read())


def loads(data: str | bytes) -> Motion:
    """Parse BVH text (``str`` or ``bytes``).

    The hierarchy is read line by line; the motion block in one compiled pass over its
    bytes (:func:`_read_block`).
    """
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if b"\x00" in raw:
        raise MotionError("not a BVH file: it contains binary data")
    if b"\n" not in raw:
        raw = raw.replace(b"\r", b"\n")  # classic Mac line endings
    header_end = _motion_keyword_end(raw)
    lines = _decode(raw[:header_end]).replace("\r", "").split("\n")
    skeleton, motion_line = _parse_hierarchy(lines)
    if header_end == len(raw):  # no MOTION line: the hierarchy parser has named the problem
        raise MotionError("unexpected end of file: expected 'MOTION'", line=len(lines))
    fps, values = _parse_motion(raw, header_end, len(lines), skeleton)
    return _to_motion(skeleton, fps, values)


_MOTION_KEYWORD = re.compile(rb"^[ \t]*MOTION[ \t\r]*$", re.MULTILINE | re.IGNORECASE)


def _motion_keyword_end(raw: bytes) -> int:
    """Offset just past the ``MOTION`` line (before its newline), or ``len(raw)`` if none.
    A joint cannot be named so as to match: its line starts with ``JOINT``."""
    match = _MOTION_KEYWORD.search(raw)
    return len(raw) if match is None else match.end()


def _decode(raw: bytes) -> str:
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
    if any(abs(v) > MAX_ABS_VALUE for v in vals):
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


class _ByteLines:
    """Non-empty stripped lines of ``raw`` from byte offset ``pos``, with 1-based numbers
    (``line`` is the number of the line ``pos`` lies on)."""

    def __init__(self, raw: bytes, pos: int, line: int) -> None:
        self.raw, self.pos, self.line = raw, pos, line

    def next(self, what: str) -> tuple[int, str]:
        while self.pos < len(self.raw):
            stop = self.raw.find(b"\n", self.pos)
            stop = len(self.raw) if stop < 0 else stop
            text = self.raw[self.pos : stop].strip()
            if self.pos > 0 and self.raw[self.pos - 1 : self.pos] == b"\n":
                self.line += 1
            self.pos = stop + 1
            if text:
                return self.line, _decode(text)
        raise MotionError(f"unexpected end of file: expected {what}", line=self.line)


def _parse_motion(raw: bytes, pos: int, line: int, skeleton: Skeleton) -> tuple[float, np.ndarray]:
    """The frame rate and the channel values ``(F, C)`` of the motion section, which starts
    after byte ``pos`` (the end of the ``MOTION`` line, line number ``line``)."""
    src = _ByteLines(raw, pos, line)
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
    channels = sum(len(c) for c in skeleton.channels)
    block = raw[src.pos :]
    values = _read_block(block, channels, first_line=n + 1)
    frames = len(values)
    if frames == 0:
        raise MotionError(f"line {n}: the file has no frames", line=n)
    if frames < declared:
        last = n + 1 + _line_of_row(block, frames - 1)
        raise MotionError(
            f"line {last}: file ends after {frames} frames, header says {declared}", line=last
        )
    return 1.0 / frame_time, values


def _read_block(block: bytes, channels: int, first_line: int) -> np.ndarray:
    """The motion block ``block`` (bytes after the ``Frame Time`` line, whose first line is
    ``first_line``) as an array ``(F, channels)``: every non-blank line one frame of
    ``channels`` finite numbers, each read as ``float()`` reads it (``bvh_kernels.read_numbers``,
    and ``float()`` itself for the few tokens it leaves). Any other block raises
    :class:`MotionError` naming the line and the problem."""
    data = np.frombuffer(block, dtype=np.uint8)
    values, slow, status, line = bvh_kernels.read_numbers(data, channels)
    if status == bvh_kernels.READ_COUNT:
        count = len(block.split(b"\n")[line].split())
        raise MotionError(
            f"line {first_line + line}: frame has {count} values, the hierarchy needs {channels}",
            line=first_line + line,
        )
    if status == bvh_kernels.READ_SLOW:  # many odd tokens: numpy's C reader, then float()
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a non-number makes fromstring warn and stop early
            try:
                values = np.fromstring(block, dtype=np.float64, sep=" ")
            except (DeprecationWarning, ValueError):
                tokens = (m.span() for m in re.finditer(rb"\S+", block))
                values = np.array([_number(block, a, b, first_line) for a, b in tokens])
    else:
        for a, b, index in slow:
            values[index] = _number(block, int(a), int(b), first_line)
    if channels == 0:  # nothing to read: a hierarchy without channels has no frames
        return np.zeros((0, 0))
    values = values.reshape(-1, channels)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        line = first_line + _line_of_row(block, row)
        raise MotionError(f"line {line}: a value is not finite", line=line)
    large = (np.abs(values) > MAX_ABS_VALUE).any(axis=1)
    if large.any():
        line = first_line + _line_of_row(block, int(np.flatnonzero(large)[0]))
        raise MotionError(f"line {line}: a value is absurdly large", line=line)
    return values


def _number(block: bytes, start: int, stop: int, first_line: int) -> float:
    """``float()`` of the token ``block[start:stop]``; a MotionError naming its line when
    it is no number."""
    try:
        return float(block[start:stop])
    except ValueError:
        line = first_line + block.count(b"\n", 0, start)
        raise MotionError(f"line {line}: a value is not a number", line=line) from None


def _line_of_row(block: bytes, row: int) -> int:
    """0-based line (within ``block``) of its ``row``-th non-blank line."""
    seen = -1
    for i, text in enumerate(block.split(b"\n")):
        if text.strip():
            seen += 1
            if seen == row:
                return i
    return 0


def _to_motion(skeleton: Skeleton, fps: float, values: np.ndarray) -> Motion:
    """Channel values ``(F, C)`` -> a motion: position channels replace offsets, rotation
    channels become quaternions (``bvh_kernels.channels_to_motion``)."""
    joints = skeleton.num_joints
    position_column = np.full((joints, 3), -1, dtype=np.int64)
    angle_column = np.full((joints, 3), -1, dtype=np.int64)
    axes = np.empty((joints, 3), dtype=np.int64)
    col = 0
    for j, chans in enumerate(skeleton.channels):
        order = skeleton.rotation_order(j)
        axes[j] = ["XYZ".index(a) for a in order]
        for c in chans:
            if c in POSITION_CHANNELS:
                position_column[j, "XYZ".index(c[0])] = col
            else:
                angle_column[j, order.index(c[0])] = col
            col += 1
    values = np.ascontiguousarray(values, dtype=np.float64)
    offsets = np.ascontiguousarray(skeleton.offsets, dtype=np.float64)
    lrot, lpos = bvh_kernels.channels_to_motion(
        values, offsets, position_column, angle_column, axes
    )
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
    return out.getvalue() + _motion_block(motion)  # the block not copied through the buffer


def _motion_block(motion: Motion) -> str:
    """The frames as text: one ``to_euler`` per rotation order over all its joints, then the
    channels picked from positions and angles as one array."""
    sk = motion.skeleton
    if not any(sk.channels):
        return "\n" * motion.num_frames
    by_order: dict[str, list[int]] = {}
    for j, chans in enumerate(sk.channels):
        if any(c in ROTATION_CHANNELS for c in chans):
            by_order.setdefault(sk.rotation_order(j), []).append(j)
    euler = np.zeros_like(motion.lpos)
    for order, joints in by_order.items():
        angles = rotations.to_euler(motion.lrot[:, joints], order)
        euler[:, joints] = kernels.unwrap_degrees(angles)  # no 360° jumps
    table = np.concatenate((motion.lpos, euler), axis=1)  # (F, 2J, 3): positions, then angles
    rows, axes = [], []
    for j, chans in enumerate(sk.channels):
        order = sk.rotation_order(j)
        for c in chans:
            position = c in POSITION_CHANNELS
            rows.append(j if position else sk.num_joints + j)
            axes.append("XYZ".index(c[0]) if position else order.index(c[0]))
    return format_fixed(table[:, rows, axes])


_FIXED_LIMIT = 1e12  # beyond this (never motion) the text goes through printf


def format_fixed(values: np.ndarray) -> str:
    """Rows of ``values (F, C)`` as text, ``%.6f`` numbers separated by spaces, one row a
    line (``bvh_kernels.format_fixed``). The same text as ``np.savetxt(fmt="%.6f")`` but for
    ties at the seventh decimal and ``-0.000000``, written ``0.000000``."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    if not np.isfinite(values).all() or np.abs(values).max(initial=0.0) >= _FIXED_LIMIT:
        buf = io.StringIO()
        np.savetxt(buf, values, fmt="%.6f", delimiter=" ")
        return buf.getvalue()
    return bvh_kernels.format_fixed(values).tobytes().decode("ascii")


def save(motion: Motion, path: str | os.PathLike) -> None:
    """Write ``motion`` as a BVH file."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(dumps(motion))

"""BVH read/write: ``load``/``loads`` to a :class:`~motion.skeleton.Motion`, ``save``/``dumps`` back.

Reads any channel order and any subset of the six channels on any joint
(3 on most CMU joints, 6 on every Bandai joint, mixed orders in one file),
End Sites, tabs, CRLF/LF/CR line endings and names with spaces (3ds Max
``Bip01 L Thigh``) or colons (Mixamo ``mixamorig:Hips``). Position channels
replace the joint's OFFSET (what Bandai, CMU and most tools mean).
Writing keeps names, offsets, End Sites, channel layout and frame time, so
``loads(dumps(m))`` reproduces ``m`` to print precision. Malformed input
raises :class:`~motion.errors.MotionError` naming the line and the problem.
A little over 600 lines: the number reader and writer are the service's hottest text code,
each with a fast path and the checked one it must agree with, kept side by side.
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
MAX_ABS_VALUE = 1e9  # offsets and channel values beyond this are damage, not motion
_MIN_FRAME_TIME = 1e-4  # 10,000 fps: no capture system records faster
_MAX_DEPTH = 256  # real rigs nest < 100 deep; deeper would overflow recursive writers
_CHUNK = 16_384  # numbers converted or formatted at a time (see _frames_at_a_time)


def load(path: str | os.PathLike) -> Motion:
    """Read a BVH file."""
    with open(path, "rb") as f:
        return loads(f.read())


def loads(data: str | bytes) -> Motion:
    """Parse BVH text (``str`` or ``bytes``).

    The hierarchy is read line by line; the motion block is read as one array
    (``np.loadtxt``'s C reader, or the checked reader behind it), so the cost is that of
    numpy's number parsing, not of a Python loop over frames.
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
    ``channels`` finite numbers. A well-formed block is read by :func:`_read_clean_block`;
    any other goes through :func:`_read_checked_block`, which names the problem."""
    values = _read_clean_block(block, channels)
    return _read_checked_block(block, channels, first_line) if values is None else values


def _read_clean_block(block: bytes, channels: int) -> np.ndarray | None:
    """``block`` read by ``np.loadtxt`` (a C reader, about three times faster than
    :func:`_read_checked_block`), or None when that reader might disagree with the checked
    one or the block has a problem: the checked reader then reads it or names the problem.
    Only ASCII with no control bytes but tab, CR and LF is tried, so that both split the
    numbers at the same bytes; both read each number as correctly rounded ``float()``."""
    if channels == 0 or not block.isascii():
        return None
    data = np.frombuffer(block, dtype=np.uint8)
    control = data[data < 32]
    if not ((control == 9) | (control == 10) | (control == 13)).all():
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an empty block warns
            values = np.loadtxt(io.BytesIO(block), dtype=np.float64, comments=None, ndmin=2)
    except (ValueError, UserWarning):
        return None
    if values.shape[1] != channels or not np.isfinite(values).all():
        return None
    if np.abs(values).max(initial=0.0) > MAX_ABS_VALUE:
        return None
    return values


def _read_checked_block(block: bytes, channels: int, first_line: int) -> np.ndarray:
    """:func:`_read_block` with every check named. One ``np.fromstring`` reads all the
    numbers; the count of numbers on each line is checked on the bytes (a space followed by a non-space starts
    one), so a line with a missing value and one with an extra value cannot cancel out.
    Plain decimals are read by :func:`_decimals`; anything it declines goes through
    ``np.fromstring``, whose failure is then traced to its line."""
    data = np.frombuffer(block, dtype=np.uint8)
    space = data <= 32  # any other control byte is no number either: fromstring refuses it
    starts = np.flatnonzero(space[:-1] > space[1:]) + 1  # a space, then a non-space
    ends = np.flatnonzero(space[1:] > space[:-1]) + 1  # a non-space, then a space
    if len(data) and not space[0]:
        starts = np.concatenate(([0], starts))
    if len(data) and not space[-1]:
        ends = np.concatenate((ends, [len(data)]))
    newlines = np.flatnonzero(data == 10)
    # numbers on each line: those that start before its newline and after the previous one
    before = np.searchsorted(starts, newlines)
    per_line = np.diff(np.concatenate(([0], before, [len(starts)])))
    filled = np.flatnonzero(per_line)
    wrong = filled[per_line[filled] != channels]
    if len(wrong):
        i = int(wrong[0])
        raise MotionError(
            f"line {first_line + i}: frame has {per_line[i]} values, the hierarchy needs "
            f"{channels}",
            line=first_line + i,
        )
    frames = len(filled)
    if channels == 0:  # nothing to read: a hierarchy without channels has no frames
        return np.zeros((0, 0))
    values = _decimals(data, block, starts, ends)
    if values is None:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a non-number makes fromstring warn and stop early
            try:
                values = np.fromstring(block, dtype=np.float64, sep=" ")
            except (DeprecationWarning, ValueError):
                values = None
    if values is None or values.size != frames * channels:
        for i in filled:
            start = 0 if i == 0 else int(newlines[i - 1]) + 1
            stop = int(newlines[i]) if i < len(newlines) else len(block)
            try:
                [float(t) for t in block[start:stop].split()]
            except ValueError:
                raise MotionError(
                    f"line {first_line + i}: a value is not a number", line=first_line + i
                ) from None
        raise MotionError(
            f"line {first_line}: the frames could not be read as numbers", line=first_line
        )
    values = values.reshape(frames, channels)
    finite = np.isfinite(values)
    if not finite.all():
        i = int(filled[np.flatnonzero(~finite.all(axis=1))[0]])
        raise MotionError(f"line {first_line + i}: a value is not finite", line=first_line + i)
    if np.abs(values).max(initial=0.0) > MAX_ABS_VALUE:
        i = int(filled[np.flatnonzero((np.abs(values) > MAX_ABS_VALUE).any(axis=1))[0]])
        raise MotionError(f"line {first_line + i}: a value is absurdly large", line=first_line + i)
    return values


_POWERS = 10.0 ** np.arange(23)
_MAX_DIGITS = 15  # below 2**53: a mantissa this long is an exact float


def _decimals(
    data: np.ndarray, block: bytes, starts: np.ndarray, ends: np.ndarray
) -> np.ndarray | None:
    """The numbers between ``starts`` and ``ends`` (byte offsets into ``data``, the bytes of
    ``block``), read column by column over all of them at once: sign, digits and one point
    give an integer mantissa M and f digits after the point, and M / 10**f is correctly
    rounded (both exact), so each equals ``float()`` of its text. Tokens it does not read
    (exponents, nan, more than 15 digits) are read by ``float()`` one by one while they
    are few; None when they are many or one is no number (the caller falls back)."""
    count = len(starts)
    if count == 0:
        return np.zeros(0)
    first = data[starts]
    negative = first == ord("-")
    begin = starts + (negative | (first == ord("+")))
    width = int((ends - begin).max())
    if width > 2 * _MAX_DIGITS:
        return None
    padded = np.concatenate((data, np.full(width + 1, 32, np.uint8)))
    mantissa = np.zeros(count, np.int64)
    after_point = np.zeros(count, np.int64)
    digits = np.zeros(count, np.int64)
    seen_point = np.zeros(count, bool)
    odd = np.zeros(count, bool)
    for column in range(width):
        at = begin + column
        inside = at < ends
        byte = padded.take(at)
        value = byte - np.uint8(ord("0"))  # wraps around below "0": no digit
        digit = (value < 10) & inside
        point = (byte == ord(".")) & inside
        odd |= (inside & ~(digit | point)) | (point & seen_point)
        seen_point |= point
        mantissa = np.where(digit, mantissa * 10 + value, mantissa)
        after_point += digit & seen_point
        digits += digit
    odd |= (digits == 0) | (digits > _MAX_DIGITS)
    out = mantissa / _POWERS[np.minimum(after_point, len(_POWERS) - 1)]
    np.negative(out, out=out, where=negative)
    rest = np.flatnonzero(odd)
    if len(rest) > max(64, count // 20):
        return None
    try:
        for i in rest:
            out[i] = float(block[starts[i] : ends[i]])
    except ValueError:
        return None
    return out


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
    channels become quaternions, one conversion per Euler order (not per joint)."""
    frames = values.shape[0]
    pos_cols, pos_joint, pos_axis = [], [], []
    rot_cols, rot_joint, rot_slot = [], [], []
    col = 0
    for j, chans in enumerate(skeleton.channels):
        order = skeleton.rotation_order(j)
        for c in chans:
            if c in POSITION_CHANNELS:
                pos_cols.append(col), pos_joint.append(j), pos_axis.append("XYZ".index(c[0]))
            else:
                rot_cols.append(col), rot_joint.append(j), rot_slot.append(order.index(c[0]))
            col += 1
    lpos = np.repeat(skeleton.offsets[None], frames, axis=0)
    lpos[:, pos_joint, pos_axis] = values[:, pos_cols]
    euler = np.zeros((frames, skeleton.num_joints, 3))
    euler[:, rot_joint, rot_slot] = values[:, rot_cols]
    lrot = np.empty((frames, skeleton.num_joints, 4))
    orders: dict[str, list[int]] = {}
    for j in range(skeleton.num_joints):
        orders.setdefault(skeleton.rotation_order(j), []).append(j)
    step = _frames_at_a_time(skeleton.num_joints)
    for order, joints in orders.items():
        for start in range(0, frames, step):  # see _frames_at_a_time
            part = slice(start, start + step)
            lrot[part, joints] = rotations.from_euler(euler[part, joints], order)
    return Motion(skeleton, fps, lrot, lpos)


def _frames_at_a_time(joints: int) -> int:
    """Frames of ``joints`` joints converted at a time: a few thousand rotations, so the
    temporaries stay in cache and in memory already mapped (freeing a large one hands
    its pages back, and the next one faults them in again): from_euler of 3,840 frames
    of 22 joints in 6.6 ms instead of 12.7."""
    return max(1, _CHUNK // (4 * max(joints, 1)))


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
        euler[:, joints] = np.rad2deg(np.unwrap(np.deg2rad(angles), axis=0))  # no 360° jumps
    table = np.concatenate((motion.lpos, euler), axis=1)  # (F, 2J, 3): positions, then angles
    rows, axes = [], []
    for j, chans in enumerate(sk.channels):
        order = sk.rotation_order(j)
        for c in chans:
            position = c in POSITION_CHANNELS
            rows.append(j if position else sk.num_joints + j)
            axes.append("XYZ".index(c[0]) if position else order.index(c[0]))
    return format_fixed(table[:, rows, axes])


def _digit_words(width: int) -> np.ndarray:
    """ASCII of ``0..10**width - 1``, zero-padded, as little-endian words (byte i, digit i)."""
    text = [f"{n:0{width}d}".encode() for n in range(10**width)]
    return np.array([int.from_bytes(t, "little") for t in text], dtype="<u8")


_DIGITS4, _DIGITS3 = _digit_words(4), _digit_words(3)
_POW10 = 10 ** np.arange(19, dtype=np.int64)
_FIXED_LIMIT = 1e12  # beyond this (never motion) the text goes through printf
# _KEEP[lead][first]: the bytes written of a number laid out in lead + 1 words that starts
# at byte first, as words
_KEEP = {
    lead: np.array([[0] * b + [1] * (8 * lead + 8 - b) for b in range(8 * lead)], "u1").view("<u8")
    for lead in (1, 2)
}


def _divide(x: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """``x // d, x % d`` of non-negative integers (numpy's // by a constant is many times
    faster than its % and divmod)."""
    q = x // d
    return q, x - q * d


def format_fixed(values: np.ndarray) -> str:
    """Rows of ``values (F, C)`` as text, ``%.6f`` numbers separated by spaces, one row a
    line. Built as one byte array, not by formatting each number in Python: each number
    is laid out as 8-byte words, its whole part right-aligned and zero-padded in the
    leading words (digits looked up four at a time), then ``.dddddd`` and the separator,
    and the unused leading bytes are dropped. The same text as ``np.savetxt(fmt="%.6f")``
    but for ties at the seventh decimal and ``-0.000000``, written ``0.000000``."""
    values = np.asarray(values, dtype=np.float64)
    frames, channels = values.shape
    if not np.isfinite(values).all() or np.abs(values).max(initial=0.0) >= _FIXED_LIMIT:
        buf = io.StringIO()
        np.savetxt(buf, values, fmt="%.6f", delimiter=" ")
        return buf.getvalue()
    step = max(1, _CHUNK // max(channels, 1))  # rows at a time, as _frames_at_a_time
    return "".join(_format_rows(values[i : i + step]) for i in range(0, max(frames, 1), step))


def _format_rows(values: np.ndarray) -> str:
    """:func:`format_fixed` of finite ``values`` below ``_FIXED_LIMIT``, all at once."""
    frames, channels = values.shape
    scaled = np.rint(values.ravel() * 1e6).astype(np.int64)
    negative = scaled < 0
    whole, fraction = _divide(np.abs(scaled), 1_000_000)
    lead = 1 + len(str(int(whole.max(initial=0)))) // 8  # words for the digits and a sign
    words = np.empty((len(scaled), lead + 1), dtype="<u8")
    eights = [whole] if lead == 1 else _divide(whole, 100_000_000)  # eight digits a word
    for w, eight in enumerate(eights):
        high, low = _divide(eight, 10_000)
        words[:, w] = _DIGITS4[high] | (_DIGITS4[low] << np.uint64(32))
    high, low = _divide(fraction, 1000)
    words[:, lead] = (_DIGITS3[high] << np.uint64(8)) | (_DIGITS3[low] << np.uint64(32))
    cells = words.view(np.uint8)  # (N, 8 * lead + 8)
    point = 8 * lead
    cells[:, point] = ord(".")
    cells[:, -1] = ord(" ")
    cells.reshape(frames, channels, point + 8)[:, -1, -1] = ord("\n")
    digits = np.searchsorted(_POW10[1:], whole, side="right") + 1
    first = point - digits - negative  # the sign's byte, or the first digit's
    signed = np.flatnonzero(negative)
    cells[signed, first[signed]] = ord("-")
    keep = _KEEP[lead].take(first, axis=0).view(bool)
    return cells[keep].tobytes().decode("ascii")


def save(motion: Motion, path: str | os.PathLike) -> None:
    """Write ``motion`` as a BVH file."""
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(dumps(motion))

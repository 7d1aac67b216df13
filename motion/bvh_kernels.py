"""The BVH motion block's numbers, compiled by numba: reading them as ``float()`` does,
writing them as ``%.6f`` does, and turning channel columns into local rotations and
positions, each in one pass over the bytes or frames.
"""

from __future__ import annotations

import numba
import numpy as np

from motion.kernels import (
    CACHE,
    DEGREE,
    euler_quaternion,
)

# statuses of read_numbers
READ_OK, READ_COUNT, READ_SLOW = 0, 1, 2
MAX_SLOW = 4096  # tokens read by float() afterwards, at most
_EXACT_DIGITS = 15  # a mantissa this long is below 2**53: an exact float
_EXACT_POWERS = 10.0 ** np.arange(23)  # exact floats too


@numba.njit(cache=CACHE, nogil=True)
def read_numbers(data: np.ndarray, channels: int) -> tuple:
    """The numbers of a motion block ``data`` (uint8 bytes), ``channels`` on each non-blank
    line, as ``(values (F * channels,), slow (K, 3), status, line)``.

    A plain decimal (sign, up to 15 digits, one point, an exponent) is exact as an integer
    mantissa times or over an exact power of ten, one correctly rounded operation: it
    equals ``float()`` of its text. Any other token (more digits, ``nan``, no number) is
    left for ``float()``: its byte span and its index in ``values`` are a row of ``slow``,
    its value NaN. ``status``: ``READ_OK``; ``READ_COUNT``, line ``line`` (0-based within
    ``data``) has another count of numbers (the values are then unfinished);
    ``READ_SLOW``, every line has the count but more than ``MAX_SLOW`` tokens are left for
    ``float()``."""
    n = data.shape[0]
    # every full row takes 2 * channels - 1 bytes or more and a row that is not full ends
    # the reading: a bound on the rows without a pass to count them (pages never written
    # are never touched)
    values = np.empty((n // max(2 * channels - 1, 1) + 1) * channels)
    slow = np.empty((MAX_SLOW, 3), np.int64)
    k = 0  # numbers read
    s = 0  # tokens left for float()
    line = 0
    on_line = 0
    i = 0
    while i < n:
        c = data[i]
        if c <= 32:
            if c == 10:
                if on_line != 0 and on_line != channels:
                    return values, slow[:s], READ_COUNT, line
                on_line = 0
                line += 1
            i += 1
            continue
        if on_line == channels:
            return values, slow[:s], READ_COUNT, line
        on_line += 1
        start = i
        negative = c == 45
        if negative or c == 43:
            i += 1
        mantissa = 0
        digits = 0
        point = -1  # digits before the point
        scale = 0
        plain = True
        while i < n:
            b = np.int64(data[i])
            if 48 <= b <= 57:
                mantissa = mantissa * 10 + (b - 48)
                digits += 1
            elif b == 46 and point < 0:
                point = digits
            elif b <= 32:
                break
            elif (b == 101 or b == 69) and digits > 0:
                i += 1
                negative_exponent = i < n and data[i] == 45
                if i < n and (data[i] == 45 or data[i] == 43):
                    i += 1
                e = 0
                length = 0
                while i < n and 48 <= data[i] <= 57:
                    e = e * 10 + (np.int64(data[i]) - 48)
                    length += 1
                    i += 1
                plain = 0 < length <= 3
                scale = -e if negative_exponent else e
                break
            else:
                plain = False
                break
            i += 1
        while i < n and data[i] > 32:  # the rest of a token that is not plain
            plain = False
            i += 1
        if point >= 0:
            scale -= digits - point
        if plain and 0 < digits <= _EXACT_DIGITS and -22 <= scale <= 22:
            value = float(mantissa)
            if scale < 0:
                value /= _EXACT_POWERS[-scale]
            elif scale > 0:
                value *= _EXACT_POWERS[scale]
            values[k] = -value if negative else value
        else:  # leading zeros count as digits here: float() reads those few
            if s < MAX_SLOW:
                slow[s, 0] = start
                slow[s, 1] = i
                slow[s, 2] = k
            s += 1
            values[k] = np.nan
        k += 1
    if on_line != 0 and on_line != channels:
        return values, slow[:s], READ_COUNT, line
    if s > MAX_SLOW:
        return values[:k], slow[:0], READ_SLOW, line
    return values[:k], slow[:s], READ_OK, line


_PAIRS = np.frombuffer(b"".join(b"%02d" % i for i in range(100)), np.uint8)  # "00".."99"


@numba.njit(cache=CACHE, nogil=True)
def format_fixed(values: np.ndarray) -> np.ndarray:
    """Rows of finite ``values (F, C)``, each below 1e12 in size, as ASCII bytes: ``%.6f``
    numbers (rounded as ``np.rint(v * 1e6)``), separated by spaces, one row a line."""
    frames, channels = values.shape
    out = np.empty(frames * channels * 22 + frames, np.uint8)
    k = 0
    for f in range(frames):
        for c in range(channels):
            scaled = np.int64(np.rint(values[f, c] * 1e6))
            if scaled < 0:
                out[k] = 45
                k += 1
                scaled = -scaled
            whole = scaled // 1_000_000
            fraction = scaled - whole * 1_000_000
            width = 1
            bound = 10
            while whole >= bound:
                width += 1
                bound *= 10
            end = k + width
            while whole >= 10:  # two digits at a time, from the last
                pair = whole % 100
                whole //= 100
                out[end - 2] = _PAIRS[2 * pair]
                out[end - 1] = _PAIRS[2 * pair + 1]
                end -= 2
            if end > k:
                out[k] = 48 + whole
            k += width
            out[k] = 46
            high = fraction // 10_000
            middle = (fraction // 100) % 100
            low = fraction % 100
            out[k + 1], out[k + 2] = _PAIRS[2 * high], _PAIRS[2 * high + 1]
            out[k + 3], out[k + 4] = _PAIRS[2 * middle], _PAIRS[2 * middle + 1]
            out[k + 5], out[k + 6] = _PAIRS[2 * low], _PAIRS[2 * low + 1]
            out[k + 7] = 32 if c < channels - 1 else 10
            k += 8
    return out[:k]


@numba.njit(cache=CACHE, nogil=True)
def channels_to_motion(values, offsets, position_column, angle_column, axes):  # pragma: no cover
    """A BVH's channel values ``(F, C)`` as local rotations ``(F, J, 4)`` and translations
    ``(F, J, 3)``: ``position_column (J, 3)`` the column of each joint's X, Y, Z position
    (-1: its offset), ``angle_column (J, 3)`` the column of each angle of its Euler order
    (-1: 0 degrees), ``axes (J, 3)`` that order's axes."""
    frames, joints = values.shape[0], offsets.shape[0]
    lrot = np.empty((frames, joints, 4))
    lpos = np.empty((frames, joints, 3))
    for f in range(frames):
        for j in range(joints):
            for a in range(3):
                col = position_column[j, a]
                lpos[f, j, a] = values[f, col] if col >= 0 else offsets[j, a]
            c0, c1, c2 = angle_column[j, 0], angle_column[j, 1], angle_column[j, 2]
            a0 = values[f, c0] * DEGREE if c0 >= 0 else 0.0
            a1 = values[f, c1] * DEGREE if c1 >= 0 else 0.0
            a2 = values[f, c2] * DEGREE if c2 >= 0 else 0.0
            euler_quaternion(a0, a1, a2, axes[j, 0], axes[j, 1], axes[j, 2], lrot[f], j)
    return lrot, lpos


def warm() -> None:
    """Compile (or load from the cache) this module's kernels for the types
    :mod:`motion.bvh` calls them with."""
    v = np.zeros((1, 3))
    format_fixed(v)
    channels_to_motion(
        v, v, np.zeros((1, 3), np.int64), np.zeros((1, 3), np.int64), np.array([[2, 0, 1]])
    )
    read_numbers(np.frombuffer(b"1 2.5e-3 x\n", np.uint8), 3)

"""The motion core's inner loops, compiled by numba: reading and writing the numbers of a
BVH motion block, and forward kinematics. Each loops over bytes or frames once, in
machine code, where numpy's version made one pass (and one temporary) per operation, and
its per-call cost was most of a short clip's.

Compiled on first use (:func:`warm` at the service's start) and cached on disk beside this
file, or in ``NUMBA_CACHE_DIR``; where neither is writable they are compiled afresh in
each process. ``nogil``: the inference pool's threads run them side by side.
"""

from __future__ import annotations

import os
import tempfile

import numba
import numpy as np


def _writable_cache() -> bool:
    """Whether numba can keep compiled code on disk: with ``cache=CACHE`` and no writable
    folder it refuses to define the function at all (a read-only install or container)."""
    folder = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.path.dirname(__file__), "__pycache__"
    )
    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


CACHE = _writable_cache()

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
    its value NaN.
        ``status``: ``READ_OK``; ``READ_COUNT``, line ``line`` (0-based within ``data``) has
        another count of numbers (the values are then unfinished); ``READ_SLOW``, every line
        has the count but more than ``MAX_SLOW`` tokens are left for ``float()``."""
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
        if c == 10:
            if on_line != 0 and on_line != channels:
                return values, slow[:s], READ_COUNT, line
            on_line = 0
            line += 1
            i += 1
            continue
        if c <= 32:
            i += 1
            continue
        start = i
        while i < n and data[i] > 32:
            i += 1
        if on_line == channels:
            return values, slow[:s], READ_COUNT, line
        on_line += 1
        j = start
        negative = data[j] == 45
        if negative or data[j] == 43:
            j += 1
        mantissa = 0
        digits = 0  # significant ones
        seen = False  # any digit
        scale = 0  # decimal exponent of the mantissa's last digit
        point = False
        plain = True
        while j < i and plain:
            b = data[j]
            j += 1
            if 48 <= b <= 57:
                seen = True
                digits += digits > 0 or b != 48
                mantissa = mantissa * 10 + (b - 48)
                scale -= point
                plain = digits <= _EXACT_DIGITS
            elif b == 46 and not point:
                point = True
            elif (b == 101 or b == 69) and seen:
                negative_exponent = j < i and data[j] == 45
                j += j < i and (data[j] == 45 or data[j] == 43)
                e = 0
                plain = 0 < i - j <= 3
                while j < i and plain:
                    b = data[j]
                    j += 1
                    plain = 48 <= b <= 57
                    e = e * 10 + (b - 48)
                scale += -e if negative_exponent else e
                break
            else:
                plain = False
        if plain and seen and -22 <= scale <= 22:
            value = float(mantissa)
            if scale < 0:
                value /= _EXACT_POWERS[-scale]
            elif scale > 0:
                value *= _EXACT_POWERS[scale]
            values[k] = -value if negative else value
        else:
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


@numba.njit(cache=CACHE, nogil=True)
def format_fixed(values: np.ndarray) -> np.ndarray:
    """Rows of finite ``values (F, C)``, each below 1e12 in size, as ASCII bytes: ``%.6f``
    numbers (rounded as ``np.rint(v * 1e6)``), separated by spaces, one row a line."""
    frames, channels = values.shape
    out = np.empty(frames * channels * 22 + frames, np.uint8)
    digits = np.empty(20, np.uint8)
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
            d = 0
            while True:
                digits[d] = 48 + whole % 10
                whole //= 10
                d += 1
                if whole == 0:
                    break
            for t in range(d - 1, -1, -1):
                out[k] = digits[t]
                k += 1
            out[k] = 46
            k += 1
            for t in range(5, -1, -1):
                out[k + t] = 48 + fraction % 10
                fraction //= 10
            k += 6
            out[k] = 32 if c < channels - 1 else 10
            k += 1
    return out[:k]


@numba.njit(cache=CACHE, nogil=True)
def fk(
    lrot: np.ndarray, lpos: np.ndarray, parents: np.ndarray, posed: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations ``(N, J, 4)`` (quaternions x, y, z, w) and positions ``(N, J, 3)``
    of local ones, parents first; joints not ``posed`` are left zero."""
    frames, joints = lrot.shape[0], lrot.shape[1]
    grot = np.zeros((frames, joints, 4))
    gpos = np.zeros((frames, joints, 3))
    for f in range(frames):
        grot[f, 0] = lrot[f, 0]
        gpos[f, 0] = lpos[f, 0]
        for j in range(1, joints):
            if not posed[j]:
                continue
            p = parents[j]
            x, y, z, w = grot[f, p, 0], grot[f, p, 1], grot[f, p, 2], grot[f, p, 3]
            vx, vy, vz = lpos[f, j, 0], lpos[f, j, 1], lpos[f, j, 2]
            tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
            gpos[f, j, 0] = (vx + w * tx + (y * tz - z * ty)) + gpos[f, p, 0]
            gpos[f, j, 1] = (vy + w * ty + (z * tx - x * tz)) + gpos[f, p, 1]
            gpos[f, j, 2] = (vz + w * tz + (x * ty - y * tx)) + gpos[f, p, 2]
            bx, by, bz, bw = lrot[f, j, 0], lrot[f, j, 1], lrot[f, j, 2], lrot[f, j, 3]
            grot[f, j, 0] = w * bx + x * bw + y * bz - z * by
            grot[f, j, 1] = w * by - x * bz + y * bw + z * bx
            grot[f, j, 2] = w * bz + x * by - y * bx + z * bw
            grot[f, j, 3] = w * bw - x * bx - y * by - z * bz
    return grot, gpos


# Quaternion arithmetic as numpy generalised ufuncs: broadcasting, any strides, one pass
# (numpy's per-component version made a dozen temporaries, 6x the time on every size).


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->(n)", cache=CACHE, nopython=True)
def quat_mul(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` (x, y, z, w)."""
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    out[0] = aw * bx + ax * bw + ay * bz - az * by
    out[1] = aw * by - ax * bz + ay * bw + az * bx
    out[2] = aw * bz + ax * by - ay * bx + az * bw
    out[3] = aw * bw - ax * bx - ay * by - az * bz


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(m)->(m)", cache=CACHE, nopython=True)
def quat_apply(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Vectors ``v (..., 3)`` rotated by unit quaternions ``q (..., 4)``."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    vx, vy, vz = v[0], v[1], v[2]
    # v + w t + q_xyz x t with t = 2 q_xyz x v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    out[0] = vx + w * tx + (y * tz - z * ty)
    out[1] = vy + w * ty + (z * tx - x * tz)
    out[2] = vz + w * tz + (x * ty - y * tx)


@numba.guvectorize(["void(f8[:], f8[:])"], "(n)->()", cache=CACHE, nopython=True)
def norm(v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Euclidean norms ``(...)`` of vectors ``(..., n)``, summed in the order of numpy's
    einsum for up to 7 components (even and odd ones apart, then together): the same
    bits as before."""
    even = 0.0
    odd = 0.0
    for i in range(0, v.shape[0] - 1, 2):
        even += v[i] * v[i]
        odd += v[i + 1] * v[i + 1]
    if v.shape[0] % 2:
        even += v[v.shape[0] - 1] * v[v.shape[0] - 1]
    out[0] = np.sqrt(even + odd)


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->(n)", cache=CACHE, nopython=True)
def cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Cross products ``(..., 3)`` of vectors ``a`` and ``b``."""
    ax, ay, az = a[0], a[1], a[2]
    bx, by, bz = b[0], b[1], b[2]
    out[0] = ay * bz - az * by
    out[1] = az * bx - ax * bz
    out[2] = ax * by - ay * bx


def warm() -> None:
    """Compile (or load from the cache) every kernel for the types the motion core calls
    them with, so that no request pays for it."""
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    v = np.zeros((1, 3))
    quat_mul(q, q)
    quat_apply(q, v)
    norm(v)
    cross(v, v)
    fk(q[None], v[None], np.zeros(1, np.int64), np.ones(1, np.bool_))
    format_fixed(v)
    read_numbers(np.frombuffer(b"1 2.5e-3 x\n", np.uint8), 3)

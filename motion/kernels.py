"""The motion core's inner loops, compiled by numba: reading and writing the numbers of a
BVH motion block, and forward kinematics. Each loops over bytes or frames once, in
machine code, where numpy's version made one pass (and one temporary) per operation, and
its per-call cost was most of a short clip's.

Compiled on first use (:func:`warm` at the service's start) and cached on disk beside this
file, or in ``NUMBA_CACHE_DIR``; where neither is writable they are compiled afresh in
each process. Several processes must not compile into one cache at once (it can be left
inconsistent, and a process loading it then crashes): ``python -m service`` compiles them
before it starts its workers. ``nogil``: the inference pool's threads run them side by
side.

About a thousand lines: every loop the motion core compiles is here, beside the inline
helpers they share (quaternion products, einsum-ordered sums, numpy's pairwise sum), so
that one module holds what must reproduce numpy's bits and one :func:`warm` compiles it.
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


# Quaternion and 3-vector arithmetic on locals, inlined into every loop below: one
# formula each, the same as numpy's per-component versions (the same bits).


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _hamilton(ax, ay, az, aw, bx, by, bz, bw):  # pragma: no cover
    """The Hamilton product ``a * b`` of two quaternions held in locals."""
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _product(a, b, out, n):  # pragma: no cover
    """``out[n] = a * b`` of quaternions held as arrays ``(4,)``."""
    out[n, 0], out[n, 1], out[n, 2], out[n, 3] = _hamilton(
        a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _apply3(x, y, z, w, v0, v1, v2):  # pragma: no cover
    t0, t1, t2 = 2.0 * (y * v2 - z * v1), 2.0 * (z * v0 - x * v2), 2.0 * (x * v1 - y * v0)
    return (
        v0 + w * t0 + (y * t2 - z * t1),
        v1 + w * t1 + (z * t0 - x * t2),
        v2 + w * t2 + (x * t1 - y * t0),
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _cross3(a0, a1, a2, b0, b1, b2):  # pragma: no cover
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover
    return (a0 * b0 + a2 * b2) + a1 * b1  # as numpy's einsum adds them


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
            q = grot[f, p]
            v0, v1, v2 = _apply3(
                q[0], q[1], q[2], q[3], lpos[f, j, 0], lpos[f, j, 1], lpos[f, j, 2]
            )
            gpos[f, j, 0] = v0 + gpos[f, p, 0]
            gpos[f, j, 1] = v1 + gpos[f, p, 1]
            gpos[f, j, 2] = v2 + gpos[f, p, 2]
            _product(grot[f, p], lrot[f, j], grot[f], j)
    return grot, gpos


@numba.njit(cache=CACHE, nogil=True)
def world_rotations(lrot: np.ndarray, parents: np.ndarray, posed: np.ndarray) -> np.ndarray:
    """Global rotations ``(N, J, 4)`` of local ones, parents first: :func:`fk` without the
    positions; joints not ``posed`` are left zero."""
    frames, joints = lrot.shape[0], lrot.shape[1]
    grot = np.zeros((frames, joints, 4))
    for f in range(frames):
        grot[f, 0] = lrot[f, 0]
        for j in range(1, joints):
            if not posed[j]:
                continue
            _product(grot[f, parents[j]], lrot[f, j], grot[f], j)
    return grot


# Quaternion arithmetic as numpy generalised ufuncs: broadcasting, any strides, one pass
# (numpy's per-component version made a dozen temporaries, 6x the time on every size).


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->(n)", cache=CACHE, nopython=True)
def quat_mul(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` (x, y, z, w)."""
    out[0], out[1], out[2], out[3] = _hamilton(a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(m)->(m)", cache=CACHE, nopython=True)
def quat_apply(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Vectors ``v (..., 3)`` rotated by unit quaternions ``q (..., 4)``."""
    out[0], out[1], out[2] = _apply3(q[0], q[1], q[2], q[3], v[0], v[1], v[2])


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _einsum_dot(a: np.ndarray, b: np.ndarray) -> float:  # pragma: no cover
    """``a . b`` added as numpy's einsum adds up to 7 components: even and odd ones apart,
    then together (the same bits as before)."""
    even = 0.0
    odd = 0.0
    for i in range(0, a.shape[0] - 1, 2):
        even += a[i] * b[i]
        odd += a[i + 1] * b[i + 1]
    if a.shape[0] % 2:
        even += a[a.shape[0] - 1] * b[a.shape[0] - 1]
    return even + odd


@numba.guvectorize(["void(f8[:], f8[:])"], "(n)->()", cache=CACHE, nopython=True)
def norm(v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Euclidean norms ``(...)`` of vectors ``(..., n)``."""
    out[0] = np.sqrt(_einsum_dot(v, v))


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->(n)", cache=CACHE, nopython=True)
def cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Cross products ``(..., 3)`` of vectors ``a`` and ``b``."""
    out[0], out[1], out[2] = _cross3(a[0], a[1], a[2], b[0], b[1], b[2])


# Rotation conversions, each the arithmetic of the numpy version it replaced in the same
# order (sums of squares as numpy's einsum adds them), so they give the same bits.

_DEGREE = np.pi / 180.0
_RADIAN = 180.0 / np.pi


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _shepperd(m00, m01, m02, m10, m11, m12, m20, m21, m22, out, n):  # pragma: no cover
    """``out[n]``: the unit quaternion of a rotation matrix by Shepperd's method, from its
    largest of w, x, y, z (no division by a small number)."""
    t0, t1, t2 = m21 - m12, m02 - m20, m10 - m01
    t3, t4, t5 = m01 + m10, m02 + m20, m12 + m21
    plus, minus = 1 + m00, 1 - m00
    w2, x2, y2 = (plus + m11) + m22, (plus - m11) - m22, (minus + m11) - m22
    z2 = (minus - m11) + m22
    if max(y2, z2) > max(w2, x2):
        q = (t4, t5, z2, t2) if z2 > y2 else (t3, y2, t5, t1)
    else:
        q = (x2, t3, t4, t0) if x2 > w2 else (t0, t1, t2, w2)
    out[n, 0], out[n, 1], out[n, 2], out[n, 3] = q
    scale = np.sqrt(
        (out[n, 0] * out[n, 0] + out[n, 2] * out[n, 2])
        + (out[n, 1] * out[n, 1] + out[n, 3] * out[n, 3])
    )
    for c in range(4):
        out[n, c] /= scale


@numba.njit(cache=CACHE, nogil=True)
def from_matrix(m: np.ndarray) -> np.ndarray:
    """Quaternions ``(N, 4)`` of matrices ``(N, 3, 3)`` (nearly orthonormal)."""
    out = np.empty((m.shape[0], 4))
    for n in range(m.shape[0]):
        _shepperd(m[n, 0, 0], m[n, 0, 1], m[n, 0, 2], m[n, 1, 0], m[n, 1, 1], m[n, 1, 2],
                  m[n, 2, 0], m[n, 2, 1], m[n, 2, 2], out, n)  # fmt: skip
    return out


@numba.njit(cache=CACHE, nogil=True)
def from_6d(r6: np.ndarray) -> np.ndarray:
    """Quaternions ``(N, 4)`` of 6D rotations ``(N, 6)`` (two matrix columns, made
    orthonormal by Gram-Schmidt)."""
    out = np.empty((r6.shape[0], 4))
    for n in range(r6.shape[0]):
        a0, a1, a2, b0, b1, b2 = r6[n, 0], r6[n, 1], r6[n, 2], r6[n, 3], r6[n, 4], r6[n, 5]
        size = max(np.sqrt((a0 * a0 + a2 * a2) + a1 * a1), 1e-12)
        x0, x1, x2 = a0 / size, a1 / size, a2 / size
        along = (x0 * b0 + x2 * b2) + x1 * b1
        b0, b1, b2 = b0 - along * x0, b1 - along * x1, b2 - along * x2
        size = max(np.sqrt((b0 * b0 + b2 * b2) + b1 * b1), 1e-12)
        y0, y1, y2 = b0 / size, b1 / size, b2 / size
        z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
        _shepperd(x0, y0, z0, x1, y1, z1, x2, y2, z2, out, n)
    return out


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _euler_quaternion(a, b, c, i, j, k, out, n):  # pragma: no cover
    """``out[n]``: the quaternion of intrinsic angles ``a, b, c`` (radians) about axes
    ``i, j, k``, the product of the three axis quaternions written out."""
    p = 1.0 if (j - i) % 3 == 1 else -1.0  # e_i x e_j = p e_k
    ha, hb, hc = a * 0.5, b * 0.5, c * 0.5
    ca, cb, cc = np.cos(ha), np.cos(hb), np.cos(hc)
    sa, sb, sc = np.sin(ha), np.sin(hb), np.sin(hc)
    cacb, sasb, sacb, casb = ca * cb, sa * sb, sa * cb, ca * sb
    out[n, i] = sacb * cc + p * casb * sc
    out[n, j] = casb * cc - p * sacb * sc
    out[n, k] = cacb * sc + p * sasb * cc
    out[n, 3] = cacb * cc - p * sasb * sc


@numba.njit(cache=CACHE, nogil=True)
def from_euler(e: np.ndarray, i: int, j: int, k: int, degrees: bool) -> np.ndarray:
    """Quaternions ``(N, 4)`` of intrinsic Euler angles ``(N, 3)`` about axes ``i, j, k``
    (R = Ri(a) Rj(b) Rk(c))."""
    scale = _DEGREE if degrees else 1.0
    out = np.empty((e.shape[0], 4))
    for n in range(e.shape[0]):
        _euler_quaternion(e[n, 0] * scale, e[n, 1] * scale, e[n, 2] * scale, i, j, k, out, n)
    return out


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
            a0 = values[f, c0] * _DEGREE if c0 >= 0 else 0.0
            a1 = values[f, c1] * _DEGREE if c1 >= 0 else 0.0
            a2 = values[f, c2] * _DEGREE if c2 >= 0 else 0.0
            _euler_quaternion(a0, a1, a2, axes[j, 0], axes[j, 1], axes[j, 2], lrot[f], j)
    return lrot, lpos


@numba.njit(cache=CACHE, nogil=True)
def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(N, 3, 3)`` of quaternions ``(N, 4)``, normalised first (a zero
    quaternion as the identity)."""
    out = np.empty((q.shape[0], 3, 3))
    for n in range(q.shape[0]):
        x, y, z, w = q[n, 0], q[n, 1], q[n, 2], q[n, 3]
        size = np.sqrt((x * x + z * z) + (y * y + w * w))
        if size > 1e-12:
            x, y, z, w = x / size, y / size, z / size, w / size
        else:
            x, y, z, w = 0.0, 0.0, 0.0, 1.0
        out[n, 0, 0] = 1 - 2 * (y * y + z * z)
        out[n, 0, 1] = 2 * (x * y - z * w)
        out[n, 0, 2] = 2 * (x * z + y * w)
        out[n, 1, 0] = 2 * (x * y + z * w)
        out[n, 1, 1] = 1 - 2 * (x * x + z * z)
        out[n, 1, 2] = 2 * (y * z - x * w)
        out[n, 2, 0] = 2 * (x * z - y * w)
        out[n, 2, 1] = 2 * (y * z + x * w)
        out[n, 2, 2] = 1 - 2 * (x * x + y * y)
    return out


# Two-bone leg IK (``motion.ik.two_bone_ik``), frame by frame on 3-vectors held in locals.


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _unit3(v0, v1, v2, f0, f1, f2, fallback):  # pragma: no cover
    """``v`` made unit, or ``f`` (with ``fallback``) where ``v`` is about zero."""
    size = np.sqrt(_dot3(v0, v1, v2, v0, v1, v2))
    if fallback and not size > 1e-12:
        return f0, f1, f2
    size = max(size, 1e-12)
    return v0 / size, v1 / size, v2 / size


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _perpendicular3(v0, v1, v2, h0, h1, h2, hinted):  # pragma: no cover
    """A unit vector perpendicular to unit ``v``: ``h``'s perpendicular part where
    ``hinted`` and it has one, else a fixed choice."""
    s0, s1, s2 = (1.0, 0.0, 0.0) if abs(v0) < 0.9 else (0.0, 0.0, 1.0)
    along = _dot3(s0, s1, s2, v0, v1, v2)
    o0, o1, o2 = _unit3(s0 - along * v0, s1 - along * v1, s2 - along * v2, 0.0, 0.0, 0.0, False)
    if hinted:
        along = _dot3(h0, h1, h2, v0, v1, v2)
        p0, p1, p2 = h0 - along * v0, h1 - along * v1, h2 - along * v2
        hint = max(np.sqrt(_dot3(h0, h1, h2, h0, h1, h2)), 1e-300)
        if np.sqrt(_dot3(p0, p1, p2, p0, p1, p2)) > 1e-9 * hint:
            return _unit3(p0, p1, p2, 0.0, 0.0, 0.0, False)
    return o0, o1, o2


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _between3(u0, u1, u2, v0, v1, v2):  # pragma: no cover
    """``motion.rotations.between`` of one pair: the shortest arc from ``u`` onto ``v``."""
    u0, u1, u2 = _unit3(u0, u1, u2, 0.0, 0.0, 0.0, False)
    v0, v1, v2 = _unit3(v0, v1, v2, 0.0, 0.0, 0.0, False)
    w = 1.0 + ((u0 * v0 + u1 * v1) + u2 * v2)
    x, y, z = _cross3(u0, u1, u2, v0, v1, v2)
    if w < 1e-9:  # opposite: any axis perpendicular to u
        x, y, z = _cross3(u0, u1, u2, 1.0, 0.0, 0.0)
        if np.sqrt(_dot3(x, y, z, x, y, z)) < 1e-6:
            x, y, z = _cross3(u0, u1, u2, 0.0, 1.0, 0.0)
        w = 0.0
    size = np.sqrt((x * x + z * z) + (y * y + w * w))
    return x / size, y / size, z / size, w / size


@numba.njit(cache=CACHE, nogil=True)
def two_bone_ik(hip, knee, ankle, target, pole, hinted, eps, pole_weight):  # pragma: no cover
    """``motion.ik.two_bone_ik`` on ``(N, 3)`` arrays (``pole`` read where ``hinted``):
    hip turns ``(N, 4)``, knee turns ``(N, 4)``, new knees and ankles ``(N, 3)``."""
    count = hip.shape[0]
    hip_turn, knee_turn = np.empty((count, 4)), np.empty((count, 4))
    knee_new, ankle_new = np.empty((count, 3)), np.empty((count, 3))
    frame = np.empty((2, 3, 3))
    for n in range(count):
        h0, h1, h2 = hip[n, 0], hip[n, 1], hip[n, 2]
        th0, th1, th2 = knee[n, 0] - h0, knee[n, 1] - h1, knee[n, 2] - h2
        sh0, sh1, sh2 = ankle[n, 0] - knee[n, 0], ankle[n, 1] - knee[n, 1], ankle[n, 2] - knee[n, 2]
        thigh_len = np.sqrt(_dot3(th0, th1, th2, th0, th1, th2))
        shin_len = np.sqrt(_dot3(sh0, sh1, sh2, sh0, sh1, sh2))
        full = thigh_len + shin_len
        r0, r1, r2 = ankle[n, 0] - h0, ankle[n, 1] - h1, ankle[n, 2] - h2
        dist_now = np.sqrt(_dot3(r0, r1, r2, r0, r1, r2))
        f0, f1, f2 = _unit3(th0, th1, th2, 0.0, -1.0, 0.0, True)
        lo0, lo1, lo2 = _unit3(r0, r1, r2, f0, f1, f2, True)
        g0, g1, g2 = target[n, 0] - h0, target[n, 1] - h1, target[n, 2] - h2
        ln0, ln1, ln2 = _unit3(g0, g1, g2, lo0, lo1, lo2, True)
        longest = min(full, max((1.0 - eps) * full, dist_now))
        folded = abs(thigh_len - shin_len)
        shortest = max(folded, min(folded + eps * full, dist_now))
        dist = min(max(np.sqrt(_dot3(g0, g1, g2, g0, g1, g2)), shortest), longest)
        along = _dot3(th0, th1, th2, lo0, lo1, lo2)
        scale = max(thigh_len, 1e-12)
        b0, b1, b2 = (
            (th0 - along * lo0) / scale,
            (th1 - along * lo1) / scale,
            (th2 - along * lo2) / scale,
        )
        i0, i1, i2 = _perpendicular3(lo0, lo1, lo2, pole[n, 0], pole[n, 1], pole[n, 2], hinted)
        straight = max(pole_weight - np.sqrt(_dot3(b0, b1, b2, b0, b1, b2)), 0.0)
        bo0, bo1, bo2 = _unit3(
            b0 + straight * i0, b1 + straight * i1, b2 + straight * i2, i0, i1, i2, True
        )
        qx, qy, qz, qw = _between3(lo0, lo1, lo2, ln0, ln1, ln2)
        bn0, bn1, bn2 = _apply3(qx, qy, qz, qw, bo0, bo1, bo2)
        along = _dot3(bn0, bn1, bn2, ln0, ln1, ln2)
        p0, p1, p2 = _perpendicular3(ln0, ln1, ln2, 0.0, 0.0, 0.0, False)
        bn0, bn1, bn2 = _unit3(
            bn0 - along * ln0, bn1 - along * ln1, bn2 - along * ln2, p0, p1, p2, True
        )
        cos_hip = (thigh_len * thigh_len + dist * dist - shin_len * shin_len) / max(
            2.0 * thigh_len * dist, 1e-12
        )
        cos_hip = min(max(cos_hip, -1.0), 1.0)
        sin_hip = np.sqrt(1.0 - cos_hip * cos_hip)
        tn0 = thigh_len * (cos_hip * ln0 + sin_hip * bn0)
        tn1 = thigh_len * (cos_hip * ln1 + sin_hip * bn1)
        tn2 = thigh_len * (cos_hip * ln2 + sin_hip * bn2)
        sn0, sn1, sn2 = dist * ln0 - tn0, dist * ln1 - tn1, dist * ln2 - tn2
        # the hip's turn: the frame (thigh, its normal to the bend plane) onto the new one
        for which in range(2):
            if which == 0:
                u0, u1, u2 = tn0, tn1, tn2
                m0, m1, m2 = _cross3(ln0, ln1, ln2, bn0, bn1, bn2)
            else:
                u0, u1, u2 = th0, th1, th2
                m0, m1, m2 = _cross3(lo0, lo1, lo2, bo0, bo1, bo2)
            x0, x1, x2 = _unit3(u0, u1, u2, 0.0, 0.0, 0.0, False)
            p0, p1, p2 = _perpendicular3(x0, x1, x2, 0.0, 0.0, 0.0, False)
            along = _dot3(m0, m1, m2, x0, x1, x2)
            y0, y1, y2 = _unit3(m0 - along * x0, m1 - along * x1, m2 - along * x2, p0, p1, p2, True)
            z0, z1, z2 = _cross3(x0, x1, x2, y0, y1, y2)
            frame[which, 0, 0], frame[which, 0, 1], frame[which, 0, 2] = x0, y0, z0
            frame[which, 1, 0], frame[which, 1, 1], frame[which, 1, 2] = x1, y1, z1
            frame[which, 2, 0], frame[which, 2, 1], frame[which, 2, 2] = x2, y2, z2
        m = np.empty((3, 3))
        for r in range(3):
            for c in range(3):
                m[r, c] = (
                    frame[0, r, 0] * frame[1, c, 0] + frame[0, r, 1] * frame[1, c, 1]
                ) + frame[0, r, 2] * frame[1, c, 2]
        _shepperd(
            m[0, 0],
            m[0, 1],
            m[0, 2],
            m[1, 0],
            m[1, 1],
            m[1, 2],
            m[2, 0],
            m[2, 1],
            m[2, 2],
            hip_turn,
            n,
        )
        hx, hy, hz, hw = hip_turn[n, 0], hip_turn[n, 1], hip_turn[n, 2], hip_turn[n, 3]
        s0, s1, s2 = _apply3(hx, hy, hz, hw, sh0, sh1, sh2)
        kx, ky, kz, kw = _between3(s0, s1, s2, sn0, sn1, sn2)
        knee_turn[n, 0], knee_turn[n, 1], knee_turn[n, 2], knee_turn[n, 3] = kx, ky, kz, kw
        k0, k1, k2 = _apply3(hx, hy, hz, hw, th0, th1, th2)
        knee_new[n, 0], knee_new[n, 1], knee_new[n, 2] = h0 + k0, h1 + k1, h2 + k2
        cx, cy, cz, cw = _hamilton(kx, ky, kz, kw, hx, hy, hz, hw)
        a0, a1, a2 = _apply3(cx, cy, cz, cw, sh0, sh1, sh2)
        ankle_new[n, 0], ankle_new[n, 1], ankle_new[n, 2] = (
            knee_new[n, 0] + a0,
            knee_new[n, 1] + a1,
            knee_new[n, 2] + a2,
        )
    return hip_turn, knee_turn, knee_new, ankle_new


# Foot contacts held still (``motion.ik._pin_offsets``).


@numba.njit(cache=CACHE, nogil=True)
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover
    """numpy's sum of at most 128 numbers: one by one below 8, else eight running sums."""
    if n < 8:
        total = 0.0
        for i in range(n):
            total += a[lo + i]
        return total
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0, r1, r2, r3 = r0 + a[lo + i], r1 + a[lo + i + 1], r2 + a[lo + i + 2], r3 + a[lo + i + 3]
        r4, r5, r6, r7 = (
            r4 + a[lo + i + 4],
            r5 + a[lo + i + 5],
            r6 + a[lo + i + 6],
            r7 + a[lo + i + 7],
        )
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += a[lo + i]
        i += 1
    return total


@numba.njit(cache=CACHE, nogil=True)
def _pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover
    """``np.sum(a[lo : lo + n])`` of a 1-D array, added in numpy's pairwise order: blocks
    of up to 128, halves (rounded to eights) added to each other. The halving runs on a
    stack of its own: numba's cached code cannot call itself."""
    if n <= 128:
        return _block_sum(a, lo, n)
    starts = np.empty(64, np.int64)
    counts = np.empty(64, np.int64)
    waiting = np.zeros(64, np.int64)  # 0: not split yet, 1: left half pending, 2: right half
    left = np.empty(64)
    top = 0
    starts[0], counts[0], waiting[0] = lo, n, 0
    value = 0.0
    returned = False
    while True:
        if returned:
            if top < 0:
                return value
            if waiting[top] == 1:  # the left half is done: on to the right one
                left[top] = value
                waiting[top] = 2
                half = counts[top] // 2
                half -= half % 8
                top += 1
                starts[top], counts[top], waiting[top] = (
                    starts[top - 1] + half,
                    counts[top - 1] - half,
                    0,
                )
                returned = False
            else:
                value = left[top] + value
                top -= 1
            continue
        if counts[top] <= 128:
            value = _block_sum(a, starts[top], counts[top])
            returned = True
            top -= 1
        else:
            waiting[top] = 1
            half = counts[top] // 2
            half -= half % 8
            top += 1
            starts[top], counts[top], waiting[top] = starts[top - 1], half, 0


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _smoothstep(x: float) -> float:  # pragma: no cover
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


@numba.njit(cache=CACHE, nogil=True)
def _runs(mask: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``(R, 2)`` starts and stops of the runs of True in ``mask``."""
    out = np.empty((mask.shape[0] // 2 + 1, 2), np.int64)
    count = 0
    inside = False
    for i in range(mask.shape[0]):
        if mask[i] and not inside:
            out[count, 0] = i
            inside = True
        elif not mask[i] and inside:
            out[count, 1] = i
            count += 1
            inside = False
    if inside:
        out[count, 1] = mask.shape[0]
        count += 1
    return out[:count]


@numba.njit(cache=CACHE, nogil=True)
def pin_offsets(ankle, toe, ankle_contact, toe_contact, ankle_ground, toe_ground, blend,
                hold_height):  # fmt: skip  # pragma: no cover
    """``motion.ik._pin_offsets`` (its docstring says what), ``toe`` and ``toe_contact``
    given (the ankle and no contact where the foot has no toe)."""
    frames = ankle.shape[0]
    roll = np.zeros(frames)
    contact = ankle_contact | toe_contact
    both = toe_contact & ankle_contact
    for f in range(frames):
        if toe_contact[f] and not ankle_contact[f]:
            roll[f] = 1.0
    for run in _runs(both):
        start, stop = run[0], run[1]
        first = 1.0 if start > 0 and roll[start - 1] == 1.0 else 0.0
        last = 0.0 if stop < frames and contact[stop] and roll[stop] == 0.0 else 1.0
        for f in range(start, stop):
            roll[f] = first + (last - first) * ((f - start + 1) / (stop - start + 1))
    anchor = np.empty((frames, 3))
    ground = np.empty(frames)
    step = np.zeros((frames, 3))
    for f in range(frames):
        ground[f] = ankle_ground + roll[f] * (toe_ground - ankle_ground)
        for c in range(3):
            anchor[f, c] = ankle[f, c] + roll[f] * (toe[f, c] - ankle[f, c])
            if f > 0:
                step[f, c] = anchor[f, c] - (
                    ankle[f - 1, c] + roll[f] * (toe[f - 1, c] - ankle[f - 1, c])
                )
    offsets = np.zeros((frames, 3))
    runs = _runs(contact)
    drift = np.empty((frames, 3))
    column = np.empty(frames)
    for run in runs:
        start, stop = run[0], run[1]
        n = stop - start
        for c in range(3):  # the anchor's slide within the contact, from its first frame
            total = 0.0
            for f in range(start, stop):
                total += step[f, c]
                drift[f, c] = total
            first = drift[start, c]
            for f in range(start, stop):
                drift[f, c] -= first
        for c in (0, 2):  # held at the slide's average on the floor
            for f in range(start, stop):
                column[f] = drift[f, c]
            mean = _pairwise_sum(column, start, n) / n
            for f in range(start, stop):
                offsets[f, c] = -drift[f, c] + mean
        for f in range(start, stop):  # and at the ground level vertically
            column[f] = ground[f] - (anchor[f, 1] - drift[f, 1])
        mean = _pairwise_sum(column, start, n) / n
        for f in range(start, stop):
            offsets[f, 1] = -drift[f, 1] + mean
    if blend > 0:  # ramps in the gaps: towards zero for long ones, straight across short
        for g in range(runs.shape[0] + 1):
            gap_start = 0 if g == 0 else runs[g - 1, 1]
            next_start = frames if g == runs.shape[0] else runs[g, 0]
            gap = next_start - gap_start
            if gap <= 0:
                continue
            for c in range(3):
                left = offsets[gap_start - 1, c] if g > 0 else 0.0
                right = offsets[next_start, c] if next_start < frames else 0.0
                for k in range(gap):
                    t = float(k + 1)
                    if g > 0 and next_start < frames and gap <= 2 * blend:
                        w = _smoothstep(t / (gap + 1))
                        value = (1.0 - w) * left + w * right
                    else:
                        fade_out = 1.0 - _smoothstep(t / (blend + 1))
                        fade_in = _smoothstep((t - gap - 1 + blend + 1) / (blend + 1))
                        value = fade_out * left + fade_in * right
                    offsets[gap_start + k, c] = value
    if not hold_height:
        for f in range(frames):
            offsets[f, 1] = max(offsets[f, 1], 0.0)
    return offsets


# Spherical interpolation (``motion.rotations.slerp``) around numpy's arccos, whose compiled
# counterpart differs in the last bit on a tenth of inputs.


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->()", cache=CACHE, nopython=True)
def dot(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Dot products ``(...)`` of vectors ``(..., n)``."""
    out[0] = _einsum_dot(a, b)


@numba.guvectorize(
    ["void(f8[:], f8[:], f8, f8, f8, f8[:])"], "(n),(n),(),(),()->(n)", cache=CACHE, nopython=True
)
def slerp_mix(a, b, t, theta, d, out):  # pragma: no cover
    """Unit quaternions ``a`` and ``b`` mixed at ``t``, ``theta = arccos(min(|d|, 1))``
    and ``d`` their dot product: the nearer of ``b`` and ``-b``, normalised."""
    s = np.sin(theta)
    small = s < 1e-6
    if small:
        s = 1.0
    sign = -1.0 if d < 0 else 1.0
    wa = 1.0 - t if small else np.sin((1.0 - t) * theta) / s
    wb = (t if small else np.sin(t * theta) / s) * sign
    q0, q1, q2, q3 = (
        wa * a[0] + wb * b[0],
        wa * a[1] + wb * b[1],
        wa * a[2] + wb * b[2],
        wa * a[3] + wb * b[3],
    )
    size = np.sqrt((q0 * q0 + q2 * q2) + (q1 * q1 + q3 * q3))
    if size > 1e-12:
        out[0], out[1], out[2], out[3] = q0 / size, q1 / size, q2 / size, q3 / size
    else:
        out[0], out[1], out[2], out[3] = 0.0, 0.0, 0.0, 1.0


@numba.njit(cache=CACHE, nogil=True)
def overlap_add(windows: np.ndarray, starts: np.ndarray, weight: np.ndarray, frames: int):
    """Windows ``(N, C, L)`` laid at ``starts`` on ``frames`` frames, each weighted by
    ``weight (L,)``, added in order: the sums ``(frames, C)`` and the weights' ``(frames,)``."""
    count, channels, length = windows.shape
    out = np.zeros((frames, channels))
    total = np.zeros(frames)
    for w in range(count):
        start = starts[w]
        for t in range(length):
            for c in range(channels):
                out[start + t, c] += weight[t] * windows[w, c, t]
            total[start + t] += weight[t]
    return out, total


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _store_local(lrot, f, j, parent, world, inverse, local):  # pragma: no cover
    """``lrot[f, j]``: the world rotation ``world`` under its parent's ``parent``, the one
    of its two quaternions on the side of the old one (the clip stays continuous);
    ``inverse (4,)`` and ``local (1, 4)`` are scratch."""
    inverse[0], inverse[1], inverse[2], inverse[3] = -parent[0], -parent[1], -parent[2], parent[3]
    _product(inverse, world, local, 0)
    old = lrot[f, j]
    agree = (local[0, 0] * old[0] + local[0, 2] * old[2]) + (
        local[0, 1] * old[1] + local[0, 3] * old[3]
    )
    for c in range(4):
        lrot[f, j, c] = -local[0, c] if agree < 0 else local[0, c]


@numba.njit(cache=CACHE, nogil=True)
def turn_leg(
    lrot, grot, parents, thigh_chain, shin_chain, ankle, frames, hip_turn, knee_turn
):  # pragma: no cover
    """``motion.ik._turn_leg``: ``lrot``'s joints of ``thigh_chain`` (hip down to above
    the knee) turned by ``hip_turn``, of ``shin_chain`` (knee down to above the ankle) by
    ``knee_turn * hip_turn``, at ``frames``, the ankle keeping its global rotation, each
    local rotation on the side of the old one (in place)."""
    joints = np.concatenate((thigh_chain, shin_chain, np.array([ankle])))
    new = np.empty((joints.shape[0], 4))
    shin = np.empty((1, 4))
    inverse = np.empty(4)
    local = np.empty((1, 4))
    for n in range(frames.shape[0]):
        f = frames[n]
        _product(knee_turn[n], hip_turn[n], shin, 0)
        for i in range(thigh_chain.shape[0]):
            _product(hip_turn[n], grot[f, thigh_chain[i]], new, i)
        for i in range(shin_chain.shape[0]):
            _product(shin[0], grot[f, shin_chain[i]], new, thigh_chain.shape[0] + i)
        new[joints.shape[0] - 1] = grot[f, ankle]
        for i in range(joints.shape[0]):
            j = joints[i]
            p = parents[j]
            parent = grot[f, p]
            for k in range(joints.shape[0]):
                if joints[k] == p:
                    parent = new[k]
            _store_local(lrot, f, j, parent, new[i], inverse, local)


@numba.njit(cache=CACHE, nogil=True)
def slerp_ends(lrot: np.ndarray, first: np.ndarray, second: np.ndarray) -> tuple:
    """The two ends of each resampled frame's slerp: ``lrot (F, J, 4)`` at frames ``first``
    and ``second`` ``(N,)``, each normalised (a zero quaternion as the identity), and
    their dot products ``(N, J)`` (as :func:`dot`)."""
    count, joints = first.shape[0], lrot.shape[1]
    a = np.empty((count, joints, 4))
    b = np.empty((count, joints, 4))
    d = np.empty((count, joints))
    for n in range(count):
        for j in range(joints):
            for end, frame in ((a, first[n]), (b, second[n])):
                x, y, z, w = (
                    lrot[frame, j, 0],
                    lrot[frame, j, 1],
                    lrot[frame, j, 2],
                    lrot[frame, j, 3],
                )
                size = np.sqrt((x * x + z * z) + (y * y + w * w))
                if size > 1e-12:
                    end[n, j, 0], end[n, j, 1], end[n, j, 2], end[n, j, 3] = (
                        x / size,
                        y / size,
                        z / size,
                        w / size,
                    )
                else:
                    end[n, j, 0], end[n, j, 1], end[n, j, 2], end[n, j, 3] = 0.0, 0.0, 0.0, 1.0
            d[n, j] = (a[n, j, 0] * b[n, j, 0] + a[n, j, 2] * b[n, j, 2]) + (
                a[n, j, 1] * b[n, j, 1] + a[n, j, 3] * b[n, j, 3]
            )
    return a, b, d


@numba.njit(cache=CACHE, nogil=True)
def unwrap_degrees(angles: np.ndarray) -> np.ndarray:
    """``np.rad2deg(np.unwrap(np.deg2rad(angles), axis=0))`` of ``angles (F, J, 3)``: each
    angle's jumps of more than 180 degrees from frame to frame taken out, the same
    arithmetic in the same order (the same bits)."""
    frames, joints = angles.shape[0], angles.shape[1]
    out = np.empty_like(angles)
    if frames == 0:
        return out
    for j in range(joints):
        for a in range(3):
            previous = angles[0, j, a] * _DEGREE
            out[0, j, a] = previous * _RADIAN
            correction = 0.0
            for f in range(1, frames):
                now = angles[f, j, a] * _DEGREE
                step = now - previous
                wrapped = np.mod(step + np.pi, 2 * np.pi) - np.pi
                if wrapped == -np.pi and step > 0:
                    wrapped = np.pi
                if not abs(step) < np.pi:
                    correction += wrapped - step
                else:
                    correction += 0.0
                out[f, j, a] = (now + correction) * _RADIAN
                previous = now
    return out


@numba.njit(cache=CACHE, nogil=True)
def lift_toes(lrot, grot, gpos, frames, lift, parent, ankle, toe):  # pragma: no cover
    """``motion.ik.lift_toes``'s turn of one ankle at ``frames``, each raising its toe by
    ``lift (F,)`` about the ankle (the foot's length kept, at most 0.999 of it up or down),
    ``lrot`` in place; ``grot``, ``gpos`` the motion's forward kinematics."""
    quaternion = np.empty((1, 4))
    turned = np.empty((1, 4))
    local = np.empty((1, 4))
    inverse = np.empty(4)
    for n in range(frames.shape[0]):
        f = frames[n]
        f0 = gpos[f, toe, 0] - gpos[f, ankle, 0]
        f1 = gpos[f, toe, 1] - gpos[f, ankle, 1]
        f2 = gpos[f, toe, 2] - gpos[f, ankle, 2]
        length = np.sqrt(_dot3(f0, f1, f2, f0, f1, f2))
        rise = min(max(f1 + lift[f], -0.999 * length), 0.999 * length)
        a0, a1, a2 = _unit3(f0 * 1.0, f1 * 0.0, f2 * 1.0, 0.0, 0.0, 1.0, True)
        reach = np.sqrt(length * length - rise * rise)
        l0 = a0 * reach + rise * 0.0
        l1 = a1 * reach + rise * 1.0
        l2 = a2 * reach + rise * 0.0
        tx, ty, tz, tw = _between3(f0, f1, f2, l0, l1, l2)
        quaternion[0, 0], quaternion[0, 1], quaternion[0, 2], quaternion[0, 3] = tx, ty, tz, tw
        _product(quaternion[0], grot[f, ankle], turned, 0)
        _store_local(lrot, f, ankle, grot[f, parent], turned[0], inverse, local)


@numba.njit(cache=CACHE, nogil=True)
def knee_hinge(grot_hip, hip, knee, ankle):  # pragma: no cover
    """``motion.ik._knee_poles``'s sums over the clip: the knee's bend axis in the thigh's
    frame ``(3,)``, and the thigh's and shin's mean lengths, added as numpy adds them
    (the columns of an ``(F, 3)`` array frame by frame, a 1-D array pairwise)."""
    frames = hip.shape[0]
    columns = np.empty((5, frames))
    for f in range(frames):
        t0, t1, t2 = knee[f, 0] - hip[f, 0], knee[f, 1] - hip[f, 1], knee[f, 2] - hip[f, 2]
        s0, s1, s2 = ankle[f, 0] - knee[f, 0], ankle[f, 1] - knee[f, 1], ankle[f, 2] - knee[f, 2]
        b0, b1, b2 = _cross3(t0, t1, t2, s0, s1, s2)
        q = grot_hip[f]
        columns[0, f], columns[1, f], columns[2, f] = _apply3(-q[0], -q[1], -q[2], q[3], b0, b1, b2)
        columns[3, f] = np.sqrt(_dot3(t0, t1, t2, t0, t1, t2))
        columns[4, f] = np.sqrt(_dot3(s0, s1, s2, s0, s1, s2))
    hinge = np.zeros(3)
    for f in range(frames):  # numpy sums an (F, 3) array's columns one frame after another
        for c in range(3):
            hinge[c] += columns[c, f]
    thigh = _pairwise_sum(columns[3], 0, frames) / frames
    shin = _pairwise_sum(columns[4], 0, frames) / frames
    return hinge, thigh, shin


@numba.njit(cache=CACHE, nogil=True)
def knee_poles(grot_hip, hip, ankle, toe, frames, hinge, mode):  # pragma: no cover
    """The knee's forward direction at ``frames`` ``(N, 3)``: across the hip-ankle line
    from the hinge axis ``hinge`` in the thigh's frame (``mode`` 0) or from the foot's
    direction on the floor (``mode`` 1)."""
    out = np.empty((frames.shape[0], 3))
    for n in range(frames.shape[0]):
        f = frames[n]
        r0, r1, r2 = ankle[f, 0] - hip[f, 0], ankle[f, 1] - hip[f, 1], ankle[f, 2] - hip[f, 2]
        if mode == 0:
            q = grot_hip[f]
            h0, h1, h2 = _apply3(q[0], q[1], q[2], q[3], hinge[0], hinge[1], hinge[2])
        else:
            w0, w2 = toe[f, 0] - ankle[f, 0], toe[f, 2] - ankle[f, 2]
            h0, h1, h2 = _cross3(w0, 0.0, w2, r0, r1, r2)
        out[n, 0], out[n, 1], out[n, 2] = _cross3(r0, r1, r2, h0, h1, h2)
    return out


def warm() -> None:
    """Compile (or load from the cache) every kernel for the types the motion core calls
    them with, so that no request pays for it."""
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    v = np.zeros((1, 3))
    quat_mul(q, q)
    quat_apply(q, v)
    norm(v)
    dot(q, q)
    slerp_mix(q, q, np.zeros(1), np.zeros(1), np.ones(1))
    cross(v, v)
    fk(q[None], v[None], np.zeros(1, np.int64), np.ones(1, np.bool_))
    world_rotations(q[None], np.zeros(1, np.int64), np.ones(1, np.bool_))
    format_fixed(v)
    from_euler(v, 2, 0, 1, True)
    channels_to_motion(
        v, v, np.zeros((1, 3), np.int64), np.zeros((1, 3), np.int64), np.array([[2, 0, 1]])
    )
    from_6d(np.zeros((1, 6)))
    from_matrix(np.eye(3)[None])
    to_matrix(q)
    unwrap_degrees(v[None])
    slerp_ends(q[None], np.zeros(1, np.int64), np.zeros(1, np.int64))
    overlap_add(np.zeros((1, 1, 1), np.float32), np.zeros(1, np.int64), np.ones(1), 1)
    pin_offsets(v, v, np.ones(1, np.bool_), np.zeros(1, np.bool_), 0.0, 0.0, 2, True)
    two_bone_ik(v, v, v, v, v, False, 1e-3, 1e-3)
    one = np.zeros(1, np.int64)
    knee_hinge(q, v, v, v)
    knee_poles(q, v, v, v, one, np.zeros(3), 0)
    turn_leg(q[None].copy(), q[None], one, one, one, 0, one, q, q)
    lift_toes(q[None].copy(), q[None], v[None], one, np.zeros(1), 0, 0, 0)
    read_numbers(np.frombuffer(b"1 2.5e-3 x\n", np.uint8), 3)

"""The motion core's compiled inner loops (numba): rotation arithmetic as numpy ufuncs,
conversions, forward kinematics, and the inline quaternion and vector helpers that
:mod:`motion.bvh_kernels` and :mod:`motion.ik_kernels` share. Each loops over bytes or
frames once, in machine code, where numpy's version made one pass (and one temporary) per
operation, and its per-call cost was most of a short clip's.

Compiled on first use (:func:`motion.compiled.warm` at the service's start) and cached on
disk beside this file, or in ``NUMBA_CACHE_DIR`` (:data:`CACHE`); where neither is
writable they are compiled afresh in each process. ``nogil``: the inference pool's threads
run them side by side.
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


@numba.njit(cache=CACHE, nogil=True, inline="always")
def hamilton(ax, ay, az, aw, bx, by, bz, bw):  # pragma: no cover
    """The Hamilton product ``a * b`` of two quaternions held in locals."""
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def store_product(a, b, out, n):  # pragma: no cover
    """``out[n] = a * b`` of quaternions held as arrays ``(4,)``."""
    out[n, 0], out[n, 1], out[n, 2], out[n, 3] = hamilton(
        a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def apply3(x, y, z, w, v0, v1, v2):  # pragma: no cover
    t0, t1, t2 = 2.0 * (y * v2 - z * v1), 2.0 * (z * v0 - x * v2), 2.0 * (x * v1 - y * v0)
    return (
        v0 + w * t0 + (y * t2 - z * t1),
        v1 + w * t1 + (z * t0 - x * t2),
        v2 + w * t2 + (x * t1 - y * t0),
    )


@numba.njit(cache=CACHE, nogil=True, inline="always")
def cross3(a0, a1, a2, b0, b1, b2):  # pragma: no cover
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@numba.njit(cache=CACHE, nogil=True, inline="always")
def dot3(a0, a1, a2, b0, b1, b2):  # pragma: no cover
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
            v0, v1, v2 = apply3(q[0], q[1], q[2], q[3], lpos[f, j, 0], lpos[f, j, 1], lpos[f, j, 2])
            gpos[f, j, 0] = v0 + gpos[f, p, 0]
            gpos[f, j, 1] = v1 + gpos[f, p, 1]
            gpos[f, j, 2] = v2 + gpos[f, p, 2]
            store_product(grot[f, p], lrot[f, j], grot[f], j)
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
            store_product(grot[f, parents[j]], lrot[f, j], grot[f], j)
    return grot


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(n)->(n)", cache=CACHE, nopython=True)
def quat_mul(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` (x, y, z, w)."""
    out[0], out[1], out[2], out[3] = hamilton(a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3])


@numba.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(m)->(m)", cache=CACHE, nopython=True)
def quat_apply(q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """Vectors ``v (..., 3)`` rotated by unit quaternions ``q (..., 4)``."""
    out[0], out[1], out[2] = apply3(q[0], q[1], q[2], q[3], v[0], v[1], v[2])


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
    out[0], out[1], out[2] = cross3(a[0], a[1], a[2], b[0], b[1], b[2])


DEGREE = np.pi / 180.0
_RADIAN = 180.0 / np.pi


@numba.njit(cache=CACHE, nogil=True, inline="always")
def shepperd(m00, m01, m02, m10, m11, m12, m20, m21, m22, out, n):  # pragma: no cover
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
        shepperd(m[n, 0, 0], m[n, 0, 1], m[n, 0, 2], m[n, 1, 0], m[n, 1, 1], m[n, 1, 2],
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
        shepperd(x0, y0, z0, x1, y1, z1, x2, y2, z2, out, n)
    return out


@numba.njit(cache=CACHE, nogil=True, inline="always")
def euler_quaternion(a, b, c, i, j, k, out, n):  # pragma: no cover
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
    scale = DEGREE if degrees else 1.0
    out = np.empty((e.shape[0], 4))
    for n in range(e.shape[0]):
        euler_quaternion(e[n, 0] * scale, e[n, 1] * scale, e[n, 2] * scale, i, j, k, out, n)
    return out


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
            previous = angles[0, j, a] * DEGREE
            out[0, j, a] = previous * _RADIAN
            correction = 0.0
            for f in range(1, frames):
                now = angles[f, j, a] * DEGREE
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


def warm() -> None:
    """Compile (or load from the cache) this module's kernels for the types the motion core
    calls them with."""
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
    from_euler(v, 2, 0, 1, True)
    from_6d(np.zeros((1, 6)))
    from_matrix(np.eye(3)[None])
    to_matrix(q)
    unwrap_degrees(v[None])
    slerp_ends(q[None], np.zeros(1, np.int64), np.zeros(1, np.int64))
    overlap_add(np.zeros((1, 1, 1), np.float32), np.zeros(1, np.int64), np.ones(1), 1)

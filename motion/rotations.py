"""Quaternion helpers, numpy and ``scipy.spatial.transform.Rotation``.

Quaternions are scipy's order ``(x, y, z, w)`` in arrays of shape ``(..., 4)``.
Products, vector rotation, cross products, norms and slerp are compiled generalised
ufuncs; Euler angles, matrices and 6D rotations are converted by compiled loops
(``motion.kernels``, the numpy arithmetic they replaced, the same bits), but for
``to_euler``'s arctangents, which stay numpy's; rotation vectors go through scipy.

Glossary: ``q`` quaternion, ``v`` 3-vector, ``m`` 3x3 matrix, ``e`` Euler angles
in degrees with a BVH channel order such as ``"ZXY"`` (intrinsic, i.e.
R = Rz @ Rx @ Ry for ``"ZXY"``), ``r6`` the continuous 6D representation (first
two columns of the matrix).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from motion import kernels

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of shape ``shape + (4,)``."""
    out = np.zeros(shape + (4,))
    out[..., 3] = 1.0
    return out


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; zero quaternions become the identity."""
    q = np.asarray(q, dtype=np.float64)
    n = norm(q)[..., None]
    if n.size and n.min() > 1e-12:  # the usual case: no zero quaternion to replace
        return q / n
    return np.where(n > 1e-12, q / np.where(n > 1e-12, n, 1.0), IDENTITY)


def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms ``(...)`` of vectors ``(..., n)``."""
    return kernels.norm(v)


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), broadcasting ``(..., 4)``."""
    return kernels.quat_mul(a, b)


def inv(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions ``(..., 4)`` (the conjugate)."""
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` (broadcasting)."""
    return kernels.quat_apply(q, v)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products ``(..., 3)`` of vectors ``a`` and ``b`` (broadcasting)."""
    return kernels.cross(a, b)


def between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking directions ``u`` onto ``v`` (``(..., 3)`` -> ``(..., 4)``).

    Opposite directions turn by 180 degrees about an axis perpendicular to ``u``.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u = u / np.maximum(norm(u), 1e-12)[..., None]
    v = v / np.maximum(norm(v), 1e-12)[..., None]
    u, v = np.broadcast_arrays(u, v)
    w = 1.0 + np.sum(u * v, axis=-1, keepdims=True)
    axis = cross(u, v)
    # for opposite vectors pick any axis perpendicular to u
    alt = cross(u, np.array([1.0, 0.0, 0.0]))
    alt2 = cross(u, np.array([0.0, 1.0, 0.0]))
    alt = np.where(norm(alt)[..., None] < 1e-6, alt2, alt)
    opposite = w < 1e-9
    axis = np.where(opposite, alt, axis)
    w = np.where(opposite, 0.0, w)
    return normalize(np.concatenate([axis, w], axis=-1))


def canonicalize(q: np.ndarray) -> np.ndarray:
    """The same rotations with ``w >= 0`` (one of the two quaternions of each rotation)."""
    q = np.asarray(q, dtype=np.float64)
    return np.where(q[..., 3:4] < 0, -q, q)


def make_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so neighbouring quaternions agree; new array.

    A quaternion is flipped when an odd number of sign changes lie between it and the
    first one: a cumulative parity over the dot products of neighbours, no loop over time.
    """
    q = np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0)
    if q.shape[0] < 2:
        return np.moveaxis(q.copy(), 0, axis)
    change = np.sum(q[1:] * q[:-1], axis=-1) < 0
    parity = np.zeros(q.shape[:-1], dtype=bool)
    parity[1:] = np.logical_xor.accumulate(change, axis=0)
    return np.moveaxis(np.where(parity[..., None], -q, q), 0, axis)


def mean(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """The mean rotation along ``axis``: the quaternion that maximises the summed squared
    agreement with all of them (Markley's eigenvector, the chordal L2 mean), sign-free."""
    q = normalize(np.moveaxis(np.asarray(q, dtype=np.float64), axis, 0))
    outer = np.einsum("n...i,n...j->...ij", q, q)
    _, vectors = np.linalg.eigh(outer)
    return canonicalize(vectors[..., :, -1])


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians ``(...,)`` of unit quaternions ``(..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def _scipy_order(order: str) -> str:
    order = order.upper()
    if len(order) != 3 or sorted(order) != ["X", "Y", "Z"]:
        raise ValueError(f"rotation order must be a permutation of XYZ, got {order!r}")
    return order  # upper case = intrinsic, which is what BVH channels mean


def _axes(order: str) -> tuple[int, int, int]:
    order = _scipy_order(order)
    return "XYZ".index(order[0]), "XYZ".index(order[1]), "XYZ".index(order[2])


def from_euler(e: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Quaternions ``(..., 4)`` from Euler angles ``(..., 3)`` listed in ``order``.

    ``order`` is the BVH channel order, e.g. ``"ZXY"``: angles ``e[..., 0]`` about Z,
    ``e[..., 1]`` about X, ``e[..., 2]`` about Y, and R = Rz @ Rx @ Ry (compiled: BVH
    reading converts every joint of every frame).
    """
    e = np.asarray(e, dtype=np.float64)
    flat = np.ascontiguousarray(e.reshape(-1, 3))
    return kernels.from_euler(flat, *_axes(order), degrees).reshape(e.shape[:-1] + (4,))


def to_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Euler angles ``(..., 3)`` in ``order`` (see :func:`from_euler`) from quaternions.

    Plain numpy on the rotation matrix R = Ri(a) Rj(b) Rk(c): b from R[i, k], a and c
    from the rest of row i and column k; at gimbal lock (|cos b| ~ 0) c is 0 and a takes
    the whole turn about the shared axis.
    """
    m = to_matrix(q)
    i, j, k = _axes(order)
    sign = 1.0 if (j - i) % 3 == 1 else -1.0  # even permutation of XYZ
    sin_b = sign * m[..., i, k]
    cos_b = np.hypot(m[..., i, i], m[..., i, j])
    b = np.arctan2(sin_b, cos_b)
    locked = cos_b < 1e-9
    a = np.where(
        locked,
        np.arctan2(sign * m[..., k, j], m[..., j, j]),
        np.arctan2(-sign * m[..., j, k], m[..., k, k]),
    )
    c = np.where(locked, 0.0, np.arctan2(-sign * m[..., i, j], m[..., i, i]))
    out = np.stack([a, b, c], axis=-1)
    return np.rad2deg(out) if degrees else out


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` (normalised first)."""
    q = np.asarray(q, dtype=np.float64)
    flat = np.ascontiguousarray(q.reshape(-1, 4))
    return kernels.to_matrix(flat).reshape(q.shape[:-1] + (3, 3))


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` from (nearly) orthonormal matrices ``(..., 3, 3)``: Shepperd's
    method (each from its largest of w, x, y, z, so no division by a small number);
    a matrix that is not quite orthonormal gives the normalised nearest quaternion."""
    m = np.asarray(m, dtype=np.float64)
    flat = np.ascontiguousarray(m.reshape(-1, 3, 3))
    return kernels.from_matrix(flat).reshape(m.shape[:-2] + (4,))


def to_6d(q: np.ndarray) -> np.ndarray:
    """Continuous 6D representation ``(..., 6)``: the first two matrix columns."""
    m = to_matrix(q)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def from_6d(r6: np.ndarray) -> np.ndarray:
    """Quaternions from 6D ``(..., 6)`` by Gram-Schmidt (inverse of :func:`to_6d`)."""
    r6 = np.asarray(r6, dtype=np.float64)
    flat = np.ascontiguousarray(r6.reshape(-1, 6))
    return kernels.from_6d(flat).reshape(r6.shape[:-1] + (4,))


def to_rotvec(q: np.ndarray) -> np.ndarray:
    """Axis-angle vectors ``(..., 3)`` (radians) from quaternions."""
    q = np.asarray(q, dtype=np.float64)
    shape = q.shape[:-1]
    return Rotation.from_quat(normalize(q).reshape(-1, 4)).as_rotvec().reshape(shape + (3,))


def from_rotvec(v: np.ndarray) -> np.ndarray:
    """Quaternions from axis-angle vectors ``(..., 3)`` (radians)."""
    v = np.asarray(v, dtype=np.float64)
    shape = v.shape[:-1]
    return Rotation.from_rotvec(v.reshape(-1, 3)).as_quat().reshape(shape + (4,))


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation from ``a`` to ``b`` (``(..., 4)``) at ``t`` (broadcasting)."""
    a = normalize(a)
    b = normalize(b)
    d = kernels.dot(a, b)
    theta = np.arccos(np.minimum(np.abs(d), 1.0))
    # t broadcasts against a.shape[:-1]
    return kernels.slerp_mix(a, b, np.asarray(t, dtype=np.float64), theta, d)


def yaw(q: np.ndarray) -> np.ndarray:
    """Rotation about +Y only, ``(..., 4)``, that points +Z where ``q`` points +Z (projected)."""
    fwd = apply(q, np.array([0.0, 0.0, 1.0]))
    ang = np.arctan2(fwd[..., 0], fwd[..., 2])
    half = 0.5 * ang
    out = np.zeros(ang.shape + (4,))
    out[..., 1] = np.sin(half)
    out[..., 3] = np.cos(half)
    return out


def about_y(angle_rad: np.ndarray) -> np.ndarray:
    """Rotations about +Y by ``angle_rad (...,)``."""
    a = np.asarray(angle_rad, dtype=np.float64)
    out = np.zeros(a.shape + (4,))
    out[..., 1] = np.sin(0.5 * a)
    out[..., 3] = np.cos(0.5 * a)
    return out

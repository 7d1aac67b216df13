"""The leg IK and foot clean-up loops of :mod:`motion.ik`, compiled by numba, frame by frame
on 3-vectors held in locals: two-bone IK, foot contacts held still, legs turned, toes
lifted, knee hinges and poles. Each reproduces the numpy version it replaced bit for bit
(sums as numpy's pairwise sum adds them).
"""

from __future__ import annotations

import numba
import numpy as np

from motion.kernels import (
    CACHE,
    apply3,
    cross3,
    dot3,
    hamilton,
    shepperd,
    store_product,
)


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _unit3(v0, v1, v2, f0, f1, f2, fallback):  # pragma: no cover
    """``v`` made unit, or ``f`` (with ``fallback``) where ``v`` is about zero."""
    size = np.sqrt(dot3(v0, v1, v2, v0, v1, v2))
    if fallback and not size > 1e-12:
        return f0, f1, f2
    size = max(size, 1e-12)
    return v0 / size, v1 / size, v2 / size


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _perpendicular3(v0, v1, v2, h0, h1, h2, hinted):  # pragma: no cover
    """A unit vector perpendicular to unit ``v``: ``h``'s perpendicular part where
    ``hinted`` and it has one, else a fixed choice."""
    s0, s1, s2 = (1.0, 0.0, 0.0) if abs(v0) < 0.9 else (0.0, 0.0, 1.0)
    along = dot3(s0, s1, s2, v0, v1, v2)
    o0, o1, o2 = _unit3(s0 - along * v0, s1 - along * v1, s2 - along * v2, 0.0, 0.0, 0.0, False)
    if hinted:
        along = dot3(h0, h1, h2, v0, v1, v2)
        p0, p1, p2 = h0 - along * v0, h1 - along * v1, h2 - along * v2
        hint = max(np.sqrt(dot3(h0, h1, h2, h0, h1, h2)), 1e-300)
        if np.sqrt(dot3(p0, p1, p2, p0, p1, p2)) > 1e-9 * hint:
            return _unit3(p0, p1, p2, 0.0, 0.0, 0.0, False)
    return o0, o1, o2


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _between3(u0, u1, u2, v0, v1, v2):  # pragma: no cover
    """``motion.rotations.between`` of one pair: the shortest arc from ``u`` onto ``v``."""
    u0, u1, u2 = _unit3(u0, u1, u2, 0.0, 0.0, 0.0, False)
    v0, v1, v2 = _unit3(v0, v1, v2, 0.0, 0.0, 0.0, False)
    w = 1.0 + ((u0 * v0 + u1 * v1) + u2 * v2)
    x, y, z = cross3(u0, u1, u2, v0, v1, v2)
    if w < 1e-9:  # opposite: any axis perpendicular to u
        x, y, z = cross3(u0, u1, u2, 1.0, 0.0, 0.0)
        if np.sqrt(dot3(x, y, z, x, y, z)) < 1e-6:
            x, y, z = cross3(u0, u1, u2, 0.0, 1.0, 0.0)
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
        thigh_len = np.sqrt(dot3(th0, th1, th2, th0, th1, th2))
        shin_len = np.sqrt(dot3(sh0, sh1, sh2, sh0, sh1, sh2))
        full = thigh_len + shin_len
        r0, r1, r2 = ankle[n, 0] - h0, ankle[n, 1] - h1, ankle[n, 2] - h2
        dist_now = np.sqrt(dot3(r0, r1, r2, r0, r1, r2))
        f0, f1, f2 = _unit3(th0, th1, th2, 0.0, -1.0, 0.0, True)
        lo0, lo1, lo2 = _unit3(r0, r1, r2, f0, f1, f2, True)
        g0, g1, g2 = target[n, 0] - h0, target[n, 1] - h1, target[n, 2] - h2
        ln0, ln1, ln2 = _unit3(g0, g1, g2, lo0, lo1, lo2, True)
        longest = min(full, max((1.0 - eps) * full, dist_now))
        folded = abs(thigh_len - shin_len)
        shortest = max(folded, min(folded + eps * full, dist_now))
        dist = min(max(np.sqrt(dot3(g0, g1, g2, g0, g1, g2)), shortest), longest)
        along = dot3(th0, th1, th2, lo0, lo1, lo2)
        scale = max(thigh_len, 1e-12)
        b0, b1, b2 = (
            (th0 - along * lo0) / scale,
            (th1 - along * lo1) / scale,
            (th2 - along * lo2) / scale,
        )
        i0, i1, i2 = _perpendicular3(lo0, lo1, lo2, pole[n, 0], pole[n, 1], pole[n, 2], hinted)
        straight = max(pole_weight - np.sqrt(dot3(b0, b1, b2, b0, b1, b2)), 0.0)
        bo0, bo1, bo2 = _unit3(
            b0 + straight * i0, b1 + straight * i1, b2 + straight * i2, i0, i1, i2, True
        )
        qx, qy, qz, qw = _between3(lo0, lo1, lo2, ln0, ln1, ln2)
        bn0, bn1, bn2 = apply3(qx, qy, qz, qw, bo0, bo1, bo2)
        along = dot3(bn0, bn1, bn2, ln0, ln1, ln2)
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
                m0, m1, m2 = cross3(ln0, ln1, ln2, bn0, bn1, bn2)
            else:
                u0, u1, u2 = th0, th1, th2
                m0, m1, m2 = cross3(lo0, lo1, lo2, bo0, bo1, bo2)
            x0, x1, x2 = _unit3(u0, u1, u2, 0.0, 0.0, 0.0, False)
            p0, p1, p2 = _perpendicular3(x0, x1, x2, 0.0, 0.0, 0.0, False)
            along = dot3(m0, m1, m2, x0, x1, x2)
            y0, y1, y2 = _unit3(m0 - along * x0, m1 - along * x1, m2 - along * x2, p0, p1, p2, True)
            z0, z1, z2 = cross3(x0, x1, x2, y0, y1, y2)
            frame[which, 0, 0], frame[which, 0, 1], frame[which, 0, 2] = x0, y0, z0
            frame[which, 1, 0], frame[which, 1, 1], frame[which, 1, 2] = x1, y1, z1
            frame[which, 2, 0], frame[which, 2, 1], frame[which, 2, 2] = x2, y2, z2
        m = np.empty((3, 3))
        for r in range(3):
            for c in range(3):
                m[r, c] = (
                    frame[0, r, 0] * frame[1, c, 0] + frame[0, r, 1] * frame[1, c, 1]
                ) + frame[0, r, 2] * frame[1, c, 2]
        shepperd(
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
        s0, s1, s2 = apply3(hx, hy, hz, hw, sh0, sh1, sh2)
        kx, ky, kz, kw = _between3(s0, s1, s2, sn0, sn1, sn2)
        knee_turn[n, 0], knee_turn[n, 1], knee_turn[n, 2], knee_turn[n, 3] = kx, ky, kz, kw
        k0, k1, k2 = apply3(hx, hy, hz, hw, th0, th1, th2)
        knee_new[n, 0], knee_new[n, 1], knee_new[n, 2] = h0 + k0, h1 + k1, h2 + k2
        cx, cy, cz, cw = hamilton(kx, ky, kz, kw, hx, hy, hz, hw)
        a0, a1, a2 = apply3(cx, cy, cz, cw, sh0, sh1, sh2)
        ankle_new[n, 0], ankle_new[n, 1], ankle_new[n, 2] = (
            knee_new[n, 0] + a0,
            knee_new[n, 1] + a1,
            knee_new[n, 2] + a2,
        )
    return hip_turn, knee_turn, knee_new, ankle_new


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


@numba.njit(cache=CACHE, nogil=True, inline="always")
def _store_local(lrot, f, j, parent, world, inverse, local):  # pragma: no cover
    """``lrot[f, j]``: the world rotation ``world`` under its parent's ``parent``, the one
    of its two quaternions on the side of the old one (the clip stays continuous);
    ``inverse (4,)`` and ``local (1, 4)`` are scratch."""
    inverse[0], inverse[1], inverse[2], inverse[3] = -parent[0], -parent[1], -parent[2], parent[3]
    store_product(inverse, world, local, 0)
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
        store_product(knee_turn[n], hip_turn[n], shin, 0)
        for i in range(thigh_chain.shape[0]):
            store_product(hip_turn[n], grot[f, thigh_chain[i]], new, i)
        for i in range(shin_chain.shape[0]):
            store_product(shin[0], grot[f, shin_chain[i]], new, thigh_chain.shape[0] + i)
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
def lift_toes(lrot, grot, gpos, frames, lift, parent, ankle, toe):  # pragma: no cover
    """``motion.grounding.lift_toes``'s turn of one ankle at ``frames``, each raising its toe by
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
        length = np.sqrt(dot3(f0, f1, f2, f0, f1, f2))
        rise = min(max(f1 + lift[f], -0.999 * length), 0.999 * length)
        a0, a1, a2 = _unit3(f0 * 1.0, f1 * 0.0, f2 * 1.0, 0.0, 0.0, 1.0, True)
        reach = np.sqrt(length * length - rise * rise)
        l0 = a0 * reach + rise * 0.0
        l1 = a1 * reach + rise * 1.0
        l2 = a2 * reach + rise * 0.0
        tx, ty, tz, tw = _between3(f0, f1, f2, l0, l1, l2)
        quaternion[0, 0], quaternion[0, 1], quaternion[0, 2], quaternion[0, 3] = tx, ty, tz, tw
        store_product(quaternion[0], grot[f, ankle], turned, 0)
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
        b0, b1, b2 = cross3(t0, t1, t2, s0, s1, s2)
        q = grot_hip[f]
        columns[0, f], columns[1, f], columns[2, f] = apply3(-q[0], -q[1], -q[2], q[3], b0, b1, b2)
        columns[3, f] = np.sqrt(dot3(t0, t1, t2, t0, t1, t2))
        columns[4, f] = np.sqrt(dot3(s0, s1, s2, s0, s1, s2))
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
            h0, h1, h2 = apply3(q[0], q[1], q[2], q[3], hinge[0], hinge[1], hinge[2])
        else:
            w0, w2 = toe[f, 0] - ankle[f, 0], toe[f, 2] - ankle[f, 2]
            h0, h1, h2 = cross3(w0, 0.0, w2, r0, r1, r2)
        out[n, 0], out[n, 1], out[n, 2] = cross3(r0, r1, r2, h0, h1, h2)
    return out


def warm() -> None:
    """Compile (or load from the cache) this module's kernels for the types :mod:`motion.ik`
    calls them with."""
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    v = np.zeros((1, 3))
    one = np.zeros(1, np.int64)
    pin_offsets(v, v, np.ones(1, np.bool_), np.zeros(1, np.bool_), 0.0, 0.0, 2, True)
    two_bone_ik(v, v, v, v, v, False, 1e-3, 1e-3)
    knee_hinge(q, v, v, v)
    knee_poles(q, v, v, v, one, np.zeros(3), 0)
    turn_leg(q[None].copy(), q[None], one, one, one, 0, one, q, q)
    lift_toes(q[None].copy(), q[None], v[None], one, np.zeros(1), 0, 0, 0)

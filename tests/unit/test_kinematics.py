"""Forward kinematics against an independent computation, and the derived features."""

from __future__ import annotations

import numpy as np

from motion import bvh
from motion import kinematics as K
from motion import rotations as rot
from tests import rigs
from tests.conftest import data_path


def _axis_matrix(axis: str, deg: np.ndarray) -> np.ndarray:
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    i = "XYZ".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3  # cyclic, so Ry gets +sin above the diagonal
    m[..., i, i] = 1
    m[..., j, j] = c
    m[..., k, k] = c
    m[..., j, k] = -s
    m[..., k, j] = s
    return m


def independent_fk(text: str) -> np.ndarray:
    """Joint positions by textbook BVH semantics: matrices multiplied in channel order,
    parsed without motion.bvh (only the hierarchy's structure is read by hand)."""
    lines = [ln.strip() for ln in text.replace("\r", "").split("\n")]
    parents, offsets, channels, stack, last = [], [], [], [], None
    i = 0
    while lines[i] != "MOTION":
        tok = lines[i].split()
        if tok and tok[0] in ("ROOT", "JOINT"):
            parents.append(stack[-1] if stack else -1)
            offsets.append(None)
            channels.append([])
            last = len(parents) - 1
        elif tok and tok[0] == "End":
            last = None
        elif tok == ["{"]:
            stack.append(last if last is not None else -2)
        elif tok == ["}"]:
            stack.pop()
        elif tok and tok[0] == "OFFSET" and stack[-1] >= 0 and offsets[stack[-1]] is None:
            offsets[stack[-1]] = np.array(tok[1:], float)
        elif tok and tok[0] == "CHANNELS":
            channels[stack[-1]] = tok[2:]
        i += 1
    data = np.array([ln.split() for ln in lines[i + 3 :] if ln], float)
    frames, nj = len(data), len(parents)
    gm = np.zeros((frames, nj, 3, 3))
    gp = np.zeros((frames, nj, 3))
    col = 0
    for j in range(nj):
        m = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()
        pos = np.broadcast_to(offsets[j], (frames, 3)).copy()
        for c in channels[j]:
            v = data[:, col]
            col += 1
            if c.endswith("position"):
                pos[:, "XYZ".index(c[0])] = v
            else:
                m = m @ _axis_matrix(c[0], v)
        p = parents[j]
        if p < 0:
            gm[:, j], gp[:, j] = m, pos
        else:
            gm[:, j] = gm[:, p] @ m
            gp[:, j] = gp[:, p] + np.einsum("fij,fj->fi", gm[:, p], pos)
    return gp


def test_fk_matches_textbook_bvh_on_fixture_variants():
    for name, m in rigs.variants(rigs.load_fixture()).items():
        text = bvh.dumps(m)
        ours = K.global_positions(bvh.loads(text))
        np.testing.assert_allclose(ours, independent_fk(text), atol=1e-3, err_msg=name)


def test_fk_matches_textbook_bvh_on_real_files():
    for parts in (
        ("bandai", "dataset-1", "dataset-1_walk_proud_001.bvh"),
        ("cmu-dance-43", "05_11_pirouette.bvh"),
        ("cmu-dance-3dsmax", "94_01_indian_dance.bvh"),
    ):
        text = data_path(*parts).read_text(errors="replace")
        ours = K.global_positions(bvh.loads(text))
        ref = independent_fk(text)
        scale = np.ptp(ref[0], axis=0).max()
        assert np.abs(ours - ref).max() < 1e-6 * max(scale, 1) * 100, parts


def test_variants_keep_world_positions():
    base = K.global_positions(rigs.load_fixture())
    for name, m in rigs.variants(rigs.load_fixture()).items():
        g = K.global_positions(m)
        if g.shape[1] == base.shape[1] + 1:
            g = g[:, 1:]
        if name.endswith("_z_up"):  # the world turned +90 degrees about X: y -> z, z -> -y
            g = np.stack([g[..., 0], g[..., 2], -g[..., 1]], axis=-1)
        factor = 5.6 if name.endswith("_cm") else 1.0
        np.testing.assert_allclose(g, base * factor, atol=1e-6 * factor * 100, err_msg=name)


def test_local_from_global_inverts_fk():
    m = rigs.load_fixture()
    grot, _ = K.fk(m.lrot, m.lpos, m.skeleton.parents)
    back = K.local_from_global(grot, m.skeleton.parents)
    assert np.all(np.abs(np.sum(back * m.lrot, -1)) > 1 - 1e-9)


def test_resample_keeps_duration_and_endpoints():
    m = bvh.load(data_path("cmu-31", "02_01.bvh"))
    r = K.resample(m, 30.0)
    assert abs((r.num_frames - 1) / 30.0 - (m.num_frames - 1) / m.fps) < 1 / 30
    np.testing.assert_allclose(K.global_positions(r)[0], K.global_positions(m)[0], atol=1e-9)
    # every 4th frame of 120 fps lands on a 30 fps frame
    g_src = K.global_positions(m)[::4]
    g_dst = K.global_positions(r)
    n = min(len(g_src), len(g_dst))
    np.testing.assert_allclose(g_dst[:n], g_src[:n], atol=0.05)


def test_resample_count_hits_exact_frame_count():
    m = rigs.load_fixture()
    r = K.resample_count(m, 24.0, 47)
    assert r.num_frames == 47 and r.fps == 24.0
    # frame 24 at 24 fps is one second in: source frame 30 at 30 fps
    np.testing.assert_allclose(r.lpos[24], m.lpos[30], atol=1e-3)
    held = K.resample_count(m, 30.0, 80)  # past the end the last pose holds
    np.testing.assert_allclose(held.lpos[-1], m.lpos[-1], atol=1e-9)


def test_quaternion_product_and_rotation_match_scipy_and_broadcast():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(1)
    a = rot.normalize(rng.normal(size=(7, 1, 4)))
    b = rot.normalize(rng.normal(size=(5, 4)))
    v = rng.normal(size=(5, 3))
    product = rot.mul(a, b)
    turned = rot.apply(a, v)
    assert product.shape == (7, 5, 4) and turned.shape == (7, 5, 3)
    want = Rotation.from_quat(np.broadcast_to(a, (7, 5, 4)).reshape(-1, 4)) * Rotation.from_quat(
        np.broadcast_to(b, (7, 5, 4)).reshape(-1, 4)
    )
    got = product.reshape(-1, 4)
    np.testing.assert_allclose(np.abs(np.sum(got * want.as_quat(), -1)), 1.0, atol=1e-12)
    np.testing.assert_allclose(
        turned.reshape(-1, 3),
        Rotation.from_quat(np.broadcast_to(a, (7, 5, 4)).reshape(-1, 4)).apply(
            np.broadcast_to(v, (7, 5, 3)).reshape(-1, 3)
        ),
        atol=1e-12,
    )
    # one quaternion and one vector, as lists
    np.testing.assert_allclose(rot.apply([0.0, 0.0, 0.0, 1.0], [1, 2, 3]), [1.0, 2.0, 3.0])
    np.testing.assert_allclose(rot.mul(b[0].tolist(), [0.0, 0.0, 0.0, 1.0]), b[0])


def test_slerp_and_6d_round_trip():
    rng = np.random.default_rng(0)
    q = rot.normalize(rng.normal(size=(100, 4)))
    back = rot.from_6d(rot.to_6d(q))
    assert np.all(np.abs(np.sum(back * q, -1)) > 1 - 1e-9)
    mid = rot.slerp(q[:-1], q[1:], 0.5)
    a = rot.angle(rot.mul(rot.inv(q[:-1]), mid))
    b = rot.angle(rot.mul(rot.inv(mid), q[1:]))
    np.testing.assert_allclose(a, b, atol=1e-7)


def test_root_velocities_of_straight_walk_point_forward():
    m = rigs.load_fixture()
    g = K.global_positions(m)
    sk = m.skeleton
    idx = sk.names.index
    fwd = K.facing_directions(
        g, idx("LeftUpLeg"), idx("RightUpLeg"), idx("LeftArm"), idx("RightArm"), smooth=2
    )
    facing = K.facing_rotations(fwd)
    vel, turn = K.root_velocities(g[:, 0], facing, m.fps)
    assert np.median(vel[:, 1]) > 3 * np.abs(np.median(vel[:, 0]))  # forward, not sideways
    assert np.abs(turn).mean() < 1.0  # rad/s, a straight walk
    local = K.root_local(g, g[:, 0], facing)
    assert local.shape == g.shape


def test_mirrored_motion_is_the_reflection_with_sides_swapped():
    from scipy.spatial.transform import Rotation

    from motion import canonical as C
    from motion.skeleton import Motion

    rng = np.random.default_rng(3)
    frames = 7
    lrot = Rotation.random(frames * len(C.JOINTS), random_state=4).as_quat()
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 1] = rng.normal(scale=30.0, size=(frames, 3))  # the hips carry the travel
    motion = Motion(C.SKELETON, C.FPS, lrot.reshape(frames, -1, 4), lpos)
    mirror = C.mirrored(motion)
    want = K.global_positions(motion)[:, C.MIRROR_INDEX] * np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(K.global_positions(mirror), want, atol=1e-9)
    assert C.INDEX["Hand_R"] == C.MIRROR_INDEX[C.INDEX["Hand_L"]]
    twice = C.mirrored(mirror)
    np.testing.assert_allclose(twice.lrot, motion.lrot)
    np.testing.assert_allclose(twice.lpos, motion.lpos)


def test_turned_turns_the_pose_and_the_steps_by_the_angle_so_far():
    from scipy.spatial.transform import Rotation

    from motion import canonical as C
    from motion.skeleton import Motion

    rng = np.random.default_rng(5)
    frames, rate, facing = 9, 1.5, 0.7
    lrot = Rotation.random(frames * len(C.JOINTS), random_state=6).as_quat().reshape(frames, -1, 4)
    lrot[:, 0] = [0.0, 0.0, 0.0, 1.0]  # joint_Root stays on the floor, unturned
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 1] = rng.normal(scale=30.0, size=(frames, 3))
    motion = Motion(C.SKELETON, C.FPS, lrot, lpos)
    out = C.turned(motion, rate, facing)
    angle = rate * np.arange(frames) / C.FPS
    about = [Rotation.from_rotvec([0.0, a, 0.0]) for a in angle]
    hips = C.INDEX["Hips"]
    before, after = K.global_positions(motion), K.global_positions(out)
    for f in range(frames):  # the body about the hips (joint_Root stays): turned by both
        turn = Rotation.from_rotvec([0.0, angle[f] + facing, 0.0])
        want = turn.apply(before[f, hips:] - before[f, hips])
        np.testing.assert_allclose(after[f, hips:] - after[f, hips], want, atol=1e-9)
    steps_before, steps_after = np.diff(before[:, hips], axis=0), np.diff(after[:, hips], axis=0)
    for f in range(1, frames):  # each step on the floor turned by the angle at its end
        want = about[f].apply(steps_before[f - 1] * [1.0, 0.0, 1.0])
        np.testing.assert_allclose(steps_after[f - 1] * [1.0, 0.0, 1.0], want, atol=1e-9)
    np.testing.assert_allclose(after[:, hips, 1], before[:, hips, 1])  # heights kept
    np.testing.assert_allclose(after[0, hips], before[0, hips])
    unturned = C.turned(motion, 0.0)
    np.testing.assert_allclose(K.global_positions(unturned), before, atol=1e-9)


def test_repose_equals_fk_after_a_joint_turns():
    motion = rigs.load_fixture()
    parents = motion.skeleton.parents
    turned = int(parents[-1])  # the parent of a leaf, e.g. an ankle
    below = [turned]
    for j in range(turned + 1, len(parents)):
        if int(parents[j]) in below:
            below.append(j)
    grot, gpos = K.fk(motion.lrot, motion.lpos, parents)
    lrot = motion.lrot.copy()
    lrot[:, turned] = rot.mul(rot.about_y(np.linspace(0, 1, motion.num_frames)), lrot[:, turned])
    K.repose(grot, gpos, lrot, motion.lpos, parents, below)
    want_rot, want_pos = K.fk(lrot, motion.lpos, parents)
    assert len(below) >= 2
    assert np.array_equal(grot, want_rot) and np.array_equal(gpos, want_pos)  # bit for bit


def test_cross_product_is_numpys():
    rng = np.random.default_rng(4)
    a, b = rng.standard_normal((50, 3)), rng.standard_normal((7, 50, 3))
    assert np.array_equal(rot.cross(a, b), np.cross(a, b))
    assert np.array_equal(rot.cross(a, [1.0, 0.0, 0.0]), np.cross(a, [1.0, 0.0, 0.0]))

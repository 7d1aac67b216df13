"""motion.features: the translator's encodings, their invariances and round trips."""

from __future__ import annotations

import numpy as np
import pytest

from motion import canonical as C
from motion import features as Fe
from motion import keypoints
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion
from tests.conftest import data_path


def synthetic_motion(frames: int = 90, seed: int = 0) -> Motion:
    """A canonical clip with smooth random joint rotations, walking forward while turning."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / C.FPS
    J = len(C.JOINTS)
    amp = rng.uniform(0.05, 0.4, size=(J, 3))
    freq = rng.uniform(0.5, 2.0, size=(J, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(J, 3))
    rotvec = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
    rotvec[:, 0] = 0.0  # joint_Root still, as on canonical clips
    lrot = rot.from_rotvec(rotvec)
    heading = 0.6 * t
    lrot[:, C.INDEX["Hips"]] = rot.mul(rot.about_y(heading), lrot[:, C.INDEX["Hips"]])
    hips = np.stack(
        [np.cumsum(np.sin(heading)) * 3, 90 + 2 * np.sin(6 * t), np.cumsum(np.cos(heading)) * 3], -1
    )
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 0] = 0.0
    lpos[:, C.INDEX["Hips"]] = hips
    return Motion(C.SKELETON, C.FPS, lrot, lpos)


def turned(motion: Motion, angle: float, shift: tuple[float, float, float]) -> Motion:
    """The same motion turned about +Y by ``angle`` radians and moved by ``shift``."""
    q = rot.about_y(np.array(angle))
    lrot = motion.lrot.copy()
    lrot[:, C.INDEX["Hips"]] = rot.mul(q, lrot[:, C.INDEX["Hips"]])
    lpos = motion.lpos.copy()
    lpos[:, C.INDEX["Hips"]] = rot.apply(q, lpos[:, C.INDEX["Hips"]]) + np.array(shift)
    return motion.replace(lrot=lrot, lpos=lpos)


def bandai_motion() -> Motion:
    from motion import bvh, retarget

    path = next(iter(sorted(data_path("bandai", "dataset-1").glob("*walk*.bvh"))))
    m = bvh.load(path)
    return retarget.to_canonical(m, retarget.make_rig(m.skeleton, m))


def test_shapes_and_dtypes():
    m = synthetic_motion(50)
    enc = Fe.encode(m)
    assert enc.content.shape == (50, Fe.CONTENT_CHANNELS) == (50, 130)
    assert enc.style3d.shape == (50, Fe.STYLE3D_CHANNELS) == (50, 63)
    assert enc.content.dtype == enc.style3d.dtype == np.float32
    s2 = Fe.style2d_from_positions(enc.gpos, 0.3, 1.0)
    assert s2.shape == (50, Fe.STYLE2D_CHANNELS) == (50, 32)
    assert Fe.OUTPUT_CHANNELS == Fe.ROTATION_CHANNELS + 1 == 127  # rotations, hips height
    np.testing.assert_array_equal(Fe.content_features(m), enc.content)
    np.testing.assert_array_equal(Fe.style3d_features(m), enc.style3d)


def test_real_clip_features_are_finite():
    m = bandai_motion()
    enc = Fe.encode(m)
    assert np.isfinite(enc.content).all() and np.isfinite(enc.style3d).all()
    # the hips stand about one leg length above the floor
    assert 0.8 < np.median(enc.content[:, Fe.ROTATION_CHANNELS]) < 1.4


@pytest.mark.parametrize("angle", [0.7, -2.5, np.pi])
def test_content_and_style_are_facing_invariant(angle):
    m = synthetic_motion(80, seed=1)
    a, b = Fe.encode(m), Fe.encode(turned(m, angle, (120.0, 0.0, -40.0)))
    np.testing.assert_allclose(a.content, b.content, atol=2e-5)
    np.testing.assert_allclose(a.style3d, b.style3d, atol=2e-5)
    # 2D views are taken relative to the clip's mean facing, so they agree too
    np.testing.assert_allclose(
        Fe.style2d_from_positions(a.gpos, 0.4), Fe.style2d_from_positions(b.gpos, 0.4), atol=1e-5
    )


def test_root_channels():
    m = synthetic_motion(60, seed=2)
    root = Fe.content_features(m)[:, Fe.ROTATION_CHANNELS :]
    np.testing.assert_allclose(root[:, 0], m.lpos[:, C.INDEX["Hips"], 1] / Fe.LEG, rtol=1e-5)
    speed = np.linalg.norm(root[:-1, 1:3], axis=-1) * Fe.LEG / C.FPS
    step = np.linalg.norm(np.diff(m.lpos[:, C.INDEX["Hips"]][:, [0, 2]], axis=0), axis=-1)
    np.testing.assert_allclose(speed, step, rtol=1e-4)


def test_decode_of_encode_returns_the_rotations():
    m = synthetic_motion(70, seed=3)
    enc = Fe.encode(m)
    lrot = Fe.rotations_from_output(enc.content[:, : Fe.OUTPUT_CHANNELS], enc.facing)
    assert lrot.shape == (70, 22, 4)
    assert rot.angle(rot.mul(rot.inv(lrot), m.lrot)).max() < 1e-3
    out = Fe.decode_motion(enc.content[:, : Fe.OUTPUT_CHANNELS], m)
    np.testing.assert_allclose(K.global_positions(out), K.global_positions(m), atol=1e-2)
    np.testing.assert_allclose(out.lpos, m.lpos, atol=1e-4)  # the content's root trajectory
    # the last channel sets the hips' height over the floor, in leg lengths; the travel stays
    lifted = enc.content[:, : Fe.OUTPUT_CHANNELS].copy()
    lifted[:, Fe.ROTATION_CHANNELS] += 0.1
    up = K.global_positions(Fe.decode_motion(lifted, m)) - K.global_positions(out)
    up = up[:, 1:]  # every joint but the root on the floor
    np.testing.assert_allclose(up[..., 1], 0.1 * Fe.LEG, atol=1e-3)
    np.testing.assert_allclose(up[..., [0, 2]], 0.0, atol=1e-3)


def test_decode_normalises_any_output():
    m = synthetic_motion(10)
    noisy = np.random.default_rng(0).normal(size=(10, Fe.OUTPUT_CHANNELS))
    lrot = Fe.rotations_from_output(noisy, Fe.encode(m).facing)
    np.testing.assert_allclose(np.linalg.norm(lrot, axis=-1), 1.0, atol=1e-9)


def test_style2d_normalisation_is_that_of_real_keypoints():
    gpos = Fe.encode(synthetic_motion(64, seed=4)).gpos
    projected = Fe.project_2d(gpos, yaw=0.5, scale=1.1)
    observed = np.zeros(22, dtype=bool)
    observed[[Fe.HIPS, *Fe.STYLE2D_JOINTS]] = True
    kp = keypoints.Keypoints2D(
        projected, np.ones((64, 22)) * observed, observed, 30.0, "openpose-body25"
    )
    normalized = keypoints.normalize(kp)
    expected = normalized[:, Fe.STYLE2D_JOINTS] - normalized[:, Fe.HIPS : Fe.HIPS + 1]
    np.testing.assert_allclose(Fe.style2d_from_keypoints(kp), expected.reshape(64, -1), atol=1e-6)
    np.testing.assert_allclose(
        Fe.style2d_from_positions(gpos, yaw=0.5, scale=1.1), expected.reshape(64, -1), atol=1e-6
    )
    # by hand: centred, divided by the median neck-to-hips length
    hips, neck = projected[:, C.INDEX["Hips"]], projected[:, C.INDEX["Neck"]]
    size = np.median(np.linalg.norm(neck - hips, axis=-1))
    np.testing.assert_allclose(normalized, (projected - hips.mean(0)) / size, atol=1e-9)


def test_style2d_ignores_scale_and_sees_the_front():
    gpos = Fe.encode(synthetic_motion(40, seed=5)).gpos
    np.testing.assert_allclose(
        Fe.style2d_from_positions(gpos, 0.2, 0.8),
        Fe.style2d_from_positions(gpos, 0.2, 1.2),
        atol=1e-6,
    )
    front = Fe.project_2d(gpos)
    # facing the camera, the character's left hand is on the image's right
    left, right = C.INDEX["Hand_L"], C.INDEX["Hand_R"]
    assert (front[:, left, 0] > front[:, right, 0]).mean() > 0.9
    assert (front[:, C.INDEX["Head"], 1] > front[:, C.INDEX["Foot_L"], 1]).all()


def test_style2d_from_keypoints_resamples_to_30_fps():
    gpos = Fe.encode(synthetic_motion(61, seed=6)).gpos
    projected = Fe.project_2d(gpos)
    slow = projected[::2]  # the same motion at 15 fps
    kp = keypoints.Keypoints2D(slow, np.ones((len(slow), 22)), np.ones(22, bool), 15.0, "coco17")
    out = Fe.style2d_from_keypoints(kp)
    assert out.shape == (61, Fe.STYLE2D_CHANNELS)


def test_time_warp_is_reversible():
    m = synthetic_motion(120, seed=7)
    for factor in (1.37, 0.6):
        warped = Fe.time_warp(m, factor)
        assert warped.num_frames == round(119 / factor) + 1
        assert warped.fps == m.fps
        back = Fe.time_warp(warped, 1.0 / factor, num_frames=m.num_frames)
        assert rot.angle(rot.mul(rot.inv(back.lrot), m.lrot)).max() < 0.05
        np.testing.assert_allclose(back.lpos, m.lpos, atol=0.5)


def test_velocity_factor_scales_with_speed():
    m = synthetic_motion(240, seed=8)
    base = Fe.velocity_factor(m)
    assert base > 0
    ratio = Fe.velocity_factor(Fe.time_warp(m, 2.0)) / base
    assert 1.8 < ratio < 2.2


def test_stats_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    arrays = {
        "content": [rng.normal(3, 2, size=(50, Fe.CONTENT_CHANNELS))],
        "style3d": [rng.normal(size=(40, Fe.STYLE3D_CHANNELS))],
        "style2d": [np.zeros((30, Fe.STYLE2D_CHANNELS))],  # constant: std floored
    }
    stats = Fe.compute_stats(arrays)
    assert (stats.std["style2d"] == Fe.STD_FLOOR).all()
    Fe.save_stats(tmp_path / "s.npz", stats)
    loaded = Fe.load_stats(tmp_path / "s.npz")
    x = arrays["content"][0]
    z = Fe.standardize(x, loaded, "content")
    assert abs(z.mean()) < 1e-4 and abs(z.std() - 1) < 1e-2
    np.testing.assert_allclose(Fe.unstandardize(z, stats, "content"), x, atol=1e-4)
    out = Fe.standardize(x[:, : Fe.OUTPUT_CHANNELS], stats, "output")
    np.testing.assert_allclose(out, z[:, : Fe.OUTPUT_CHANNELS], atol=1e-6)


def test_pad_frames():
    x = np.arange(10.0).reshape(5, 2)
    padded = Fe.pad_frames(x, 4)
    assert padded.shape == (8, 2)
    np.testing.assert_array_equal(padded[5:], np.repeat(x[-1:], 3, axis=0))
    assert Fe.pad_frames(x[:4], 4).shape == (4, 2)


def test_wrong_frame_rate_is_refused():
    m = synthetic_motion(10).replace(fps=60.0)
    with pytest.raises(MotionError):
        Fe.encode(m)


def test_real_video_keypoints_share_the_2d_encoding():
    kp = keypoints.load(data_path("keypoints", "openpose-treadmill-27"))
    out = Fe.style2d_from_keypoints(kp)
    assert out.shape[1] == Fe.STYLE2D_CHANNELS and np.isfinite(out).all()
    # the torso is the unit in both paths: the Neck sits one median torso length from the Hips
    neck = Fe.STYLE2D_JOINTS.index(C.INDEX["Neck"])
    real = np.linalg.norm(out.reshape(len(out), -1, 2)[:, neck], axis=-1)
    projected = Fe.style2d_from_positions(Fe.encode(synthetic_motion(60)).gpos, 0.3)
    synthetic = np.linalg.norm(projected.reshape(60, -1, 2)[:, neck], axis=-1)
    assert abs(np.median(real) - 1.0) < 1e-6 and abs(np.median(synthetic) - 1.0) < 1e-6

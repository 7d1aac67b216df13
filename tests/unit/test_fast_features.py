"""The fast networks' encoding (motion.fast_features): round trip, facing invariance, stats."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh, retarget
from motion import canonical as C
from motion import fast_features as FF
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from tests.rigs import FIXTURE


@pytest.fixture(scope="module")
def canon():
    motion = bvh.load(FIXTURE)
    return retarget.to_canonical(motion, retarget.make_rig(motion.skeleton, motion))


def test_channels():
    assert FF.CHANNELS == 21 * 3 + 3 + 4 == 70
    assert FF.CONTACTS == slice(66, 70)
    child, parent, length = FF.bone_pairs()
    assert len(child) == len(parent) == len(length) == 20
    assert np.all(length > 0)


def test_positions_round_trip(canon):
    gpos = K.global_positions(canon)
    enc = FF.encode(canon)
    assert enc.features.shape == (canon.num_frames, FF.CHANNELS)
    assert enc.features.dtype == np.float32
    back, contacts = FF.decode(enc.features, enc.start, enc.heading)
    assert back.shape == gpos.shape
    # float32 features: well under a millimetre on a 170 cm character
    np.testing.assert_allclose(back[:, 1:], gpos[:, 1:], atol=0.02)
    np.testing.assert_array_equal(contacts, enc.features[:, FF.CONTACTS] > 0.5)
    assert contacts.any() and not contacts.all()  # a walk plants and lifts its feet


def test_features_are_facing_and_position_invariant(canon):
    gpos = K.global_positions(canon)
    turned = rot.apply(rot.about_y(1.3), gpos) + np.array([120.0, 0.0, -40.0])
    a = FF.encode_positions(gpos).features
    b = FF.encode_positions(turned).features
    np.testing.assert_allclose(a, b, atol=1e-4)
    # and decoding from the turned clip's start lands on the turned clip
    enc = FF.encode_positions(turned)
    back, _ = FF.decode(enc.features, enc.start, enc.heading)
    np.testing.assert_allclose(back[:, 1:], turned[:, 1:], atol=0.02)


def test_velocity_channels_move_the_root_forward(canon):
    enc = FF.encode(canon)
    forward = enc.features[:, FF.VELOCITY][:, 1]
    assert forward.mean() > 0.3  # walking forward, leg lengths per second


def test_stats_normalise_round_trip(tmp_path, canon):
    x = FF.encode(canon).features
    stats = FF.FastStats.fit([x, x[::2]])
    z = stats.normalize(x)
    np.testing.assert_allclose(stats.denormalize(z), x, atol=1e-5)
    assert np.all(stats.std[: FF.POSITION_CHANNELS] == stats.std[0])
    np.testing.assert_array_equal(stats.mean[FF.CONTACTS], 0.5)
    np.testing.assert_array_equal(np.unique(z[:, FF.CONTACTS]), [-1.0, 1.0])
    stats.save(tmp_path / "s.npz")
    loaded = FF.FastStats.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(loaded.mean, stats.mean)
    np.testing.assert_array_equal(loaded.std, stats.std)


def test_rejects_non_canonical_and_bad_shapes():
    motion = bvh.load(FIXTURE)
    with pytest.raises(MotionError):
        FF.encode(motion)
    with pytest.raises(MotionError):
        FF.decode(np.zeros((5, 3)))
    with pytest.raises(MotionError):
        FF.encode_positions(np.zeros((0, len(C.JOINTS), 3)))


def test_single_frame_clip():
    gpos = K.fk(rot.identity((1, len(C.JOINTS))), C.OFFSETS[None], C.PARENTS)[1]
    enc = FF.encode_positions(gpos)
    back, _ = FF.decode(enc.features, enc.start, enc.heading)
    np.testing.assert_allclose(back[:, 1:], gpos[:, 1:], atol=1e-3)

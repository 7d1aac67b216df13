"""The judges' features, their mirror images, and the convolutional style classifier."""

from __future__ import annotations

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from tests.rigs import FIXTURE
from training import judges as ES


def test_mirror_swaps_sides_and_keeps_what_has_no_side():
    motion = retarget.to_canonical(bvh.load(FIXTURE))
    plain, mirrored = ES.window_features(motion), ES.window_features(motion, mirror=True)
    assert plain.shape == mirrored.shape and not np.allclose(plain, mirrored)
    joints = len(C.JOINTS)
    speeds = slice(3 * joints, 4 * joints)  # per-frame layout: positions, speeds, root...
    left, right = C.INDEX["Hand_L"], C.INDEX["Hand_R"]
    np.testing.assert_allclose(plain[:, speeds][:, left], mirrored[:, speeds][:, right])
    tail = slice(4 * joints, 4 * joints + 4)  # root speeds, turning, hips height
    np.testing.assert_allclose(np.abs(plain[:, tail]), np.abs(mirrored[:, tail]), atol=1e-6)
    twice = [ES._MIRROR[j] for j in ES._MIRROR]
    assert twice == list(range(joints))


def test_frame_features_mirror_swaps_sides():
    motion = retarget.to_canonical(bvh.load(FIXTURE))
    plain, mirrored = ES.frame_features(motion), ES.frame_features(motion, mirror=True)
    assert plain.shape == mirrored.shape == (motion.num_frames, 130)
    body = [C.JOINTS[j] for j in range(1, len(C.JOINTS))]
    left, right = body.index("Hand_L"), body.index("Hand_R")
    pos = lambda f, j: f[:, 3 * j : 3 * j + 3]  # noqa: E731
    np.testing.assert_allclose(pos(mirrored, right), pos(plain, left) * [-1, 1, 1], atol=1e-6)
    np.testing.assert_allclose(mirrored[:, -4], plain[:, -4])  # hips height has no side
    np.testing.assert_allclose(mirrored[:, -1], -plain[:, -1])  # turning left becomes right


def test_frame_features_do_not_see_where_the_floor_lies():
    """A clip raised or lowered whole is the same performance on another floor: the style
    judge must read the same features."""
    motion = retarget.to_canonical(bvh.load(FIXTURE))
    hips = C.INDEX["Hips"]

    def raised(by):
        lpos = motion.lpos.copy()
        lpos[:, hips, 1] += by
        return motion.replace(lpos=lpos)

    plain = ES.frame_features(motion)
    for by in (-12.0, 8.0):  # cm: foreign clips' floors against Bandai's
        np.testing.assert_allclose(ES.frame_features(raised(by)), plain, atol=1e-4)


def test_conv_classifier_learns_what_tells_clips_apart(monkeypatch):
    rng = np.random.default_rng(0)
    features, labels = [], []
    for k, label in enumerate(("calm", "lively")):
        for _ in range(4):  # "lively" clips oscillate fast in one channel, "calm" ones slowly
            t = np.arange(rng.integers(30, 90))
            x = 0.3 * rng.normal(size=(len(t), 6))
            x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2))
            features.append(x.astype(np.float32))
            labels.append(label)
    import torch

    train, seen = ES.ConvClipClassifier._train_on_this_thread, []
    monkeypatch.setattr(
        ES.ConvClipClassifier, "_train_on_this_thread",
        lambda self, *a: seen.append(torch.get_num_threads()) or train(self, *a),
    )  # fmt: skip
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        clf = ES.ConvClipClassifier(features, labels, seeds=(0,), steps=150)
        assert seen == [1] and torch.get_num_threads() == 2  # one thread, the caller's kept
    finally:
        torch.set_num_threads(threads)
    t = np.arange(70)
    for k, label in enumerate(("calm", "lively")):
        x = 0.3 * rng.normal(size=(len(t), 6))
        x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2) + 1.0)
        assert clf.predict(x.astype(np.float32)) == label


def test_jerk_sees_jitter_and_tempo_not_where_the_body_stands():
    """Jerk reads how the joints move over the root on the floor: a tremor added to the rotations
    raises it, the walk played faster raises it and slower lowers it, and the body moved
    whole leaves it as it was."""
    from motion import rotations as rot
    from motion.features import time_warp

    motion = retarget.to_canonical(bvh.load(FIXTURE))
    calm = ES.jerk(motion)
    assert calm > 0.0
    tremor = np.random.default_rng(0).normal(0.0, 0.01, motion.lrot.shape[:2] + (3,))
    shaken = motion.replace(lrot=rot.mul(motion.lrot, rot.from_rotvec(tremor)))
    assert ES.jerk(shaken) > 3.0 * calm
    assert ES.jerk(time_warp(motion, 0.5)) < calm < ES.jerk(time_warp(motion, 2.0))
    moved = motion.lpos.copy()
    moved[:, 0] += [150.0, 20.0, -300.0]
    assert np.isclose(ES.jerk(motion.replace(lpos=moved)), calm, rtol=1e-6)


def test_the_legs_jerk_sees_the_legs_only():
    """A tremor of the arms shakes the body's jerk and leaves the legs' as it was; one of the
    knees raises the legs'."""
    from motion import rotations as rot

    motion = retarget.to_canonical(bvh.load(FIXTURE))
    legs = ES.jerk(motion, ES.LEGS)
    assert {C.JOINTS[j] for j in ES.LEGS} == {
        f"{p}_{s}" for s in "LR" for p in ("UpperLeg", "LowerLeg", "Foot", "Toes")
    }

    def shaken(names: list[str]):
        tremor = np.zeros(motion.lrot.shape[:2] + (3,))
        idx = [C.INDEX[n] for n in names]
        tremor[:, idx] = np.random.default_rng(0).normal(
            0.0, 0.02, (motion.num_frames, len(idx), 3)
        )
        return motion.replace(lrot=rot.mul(motion.lrot, rot.from_rotvec(tremor)))

    arms = shaken(["UpperArm_L", "UpperArm_R", "LowerArm_L", "LowerArm_R"])
    assert ES.jerk(arms) > 2.0 * ES.jerk(motion)
    assert np.isclose(ES.jerk(arms, ES.LEGS), legs, rtol=1e-6)
    assert ES.jerk(shaken(["LowerLeg_L", "LowerLeg_R"]), ES.LEGS) > 3.0 * legs

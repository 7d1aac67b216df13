"""The evaluation's window features, and their mirror images."""

from __future__ import annotations

import numpy as np

from motion import bvh, retarget
from motion import canonical as C
from tests.rigs import FIXTURE
from training import eval_style as ES


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


def test_conv_classifier_learns_what_tells_clips_apart():
    rng = np.random.default_rng(0)
    features, labels = [], []
    for k, label in enumerate(("calm", "lively")):
        for _ in range(4):  # "lively" clips oscillate fast in one channel, "calm" ones slowly
            t = np.arange(rng.integers(30, 90))
            x = 0.3 * rng.normal(size=(len(t), 6))
            x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2))
            features.append(x.astype(np.float32))
            labels.append(label)
    clf = ES.ConvClipClassifier(features, labels, seeds=(0,), steps=150)
    t = np.arange(70)
    for k, label in enumerate(("calm", "lively")):
        x = 0.3 * rng.normal(size=(len(t), 6))
        x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2) + 1.0)
        assert clf.predict(x.astype(np.float32)) == label


def test_tally_counts_both_content_classifiers_and_the_table_shows_them():
    t = ES.Tally()
    t.add(ES.Verdict("angry", "sad", "walk", "run", 2.0), "angry", "walk")
    t.add(ES.Verdict("sad", "sad", "run", "run", 4.0), "angry", "run")
    row = t.summary()
    assert row["style_accuracy"] == 0.5 and row["style_accuracy_linear"] == 0.0
    assert row["content_accuracy"] == 1.0 and row["content_accuracy_conv"] == 0.5
    report = {
        "family": "translator", "model": "m 1", "held_out_takes": 2, "takes_of": "translator",
        "takes_unseen_by_family": 2, "styles": 2, "chance_style": 0.5, "chance_content": 0.5,
        "rows": {"translator": row}, "per_style": {}, "per_style_real_target": {},
    }  # fmt: skip
    table = ES.markdown(report)
    assert "content accuracy (conv)" in table
    assert "| translator | 2 | 50.0% | 0.0% | 100.0% | 50.0% | 3.0 |" in table

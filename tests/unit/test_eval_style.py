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

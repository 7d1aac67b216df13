"""Root motion as a game engine wants it: kept (the default) or in place.

In place, the hips' horizontal travel is taken out of the clip and everything else kept:
the vertical bob, the facing and its turns, the limbs. The travel is measured on the hips
(where every rig's body is) and removed from the topmost joints' translations (where a
rig's root motion lives, the hips themselves or a root bone above them), in the upright
world of the file (``up`` turns the file's world so +Y is up).
"""

from __future__ import annotations

import numpy as np

from motion import kinematics as K
from motion import rotations as R
from motion.skeleton import Motion

ROOT_MOTION = ("keep", "in_place")


def in_place(motion: Motion, hips: int, up: np.ndarray | None = None) -> Motion:
    """``motion`` with joint ``hips`` held over where it starts on the floor."""
    if motion.num_frames == 0:
        return motion
    up = R.IDENTITY if up is None else np.asarray(up, dtype=np.float64)
    gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents, [hips])[1][:, hips]
    upright = R.apply(up, gpos)
    travel = upright - upright[0]
    travel[:, 1] = 0.0
    world = R.apply(R.inv(up), travel)
    lpos = motion.lpos.copy()
    roots = np.nonzero(motion.skeleton.parents < 0)[0]
    lpos[:, roots] -= world[:, None]
    return motion.replace(lpos=lpos)

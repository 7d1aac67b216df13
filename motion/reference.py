"""Leading reference frames: a bind or T-pose that a capture export puts before the motion.

Such a frame is not motion: it lies near a rest pose (the rig's own, or a T-pose), and the
first captured frame follows it with a jump. :func:`leading_reference_frames` counts them
so that the service can give them back unchanged and keep them from the networks (which
would read the jump as motion and bend the pose). Poses are compared as joint positions
about the hips, the hips' heading turned to +Z, on the canonical skeleton.

Thresholds, measured on the 24 foreign takes ``make eval-foreign`` reads: each ``cmu-31``
take opens with cgspeed's T-pose frame, 0.017-0.033 of body height from the canonical
T-pose (no motion frame of any take comes within 0.043), then jumps 11-66 median steps to
motion that goes on at about one step a frame (07_12 has two: its second frame is the
rig's rest pose itself, 125 steps from the next); the CMU dance pirouette opens with one
too (0.007, then 25 steps, then 7). The dance takes that start near a T-pose (0.039-0.045)
and fast (60_01: 8.8, 7.9, 5.4 steps) are motion: the step after is nearly as large.
"""

from __future__ import annotations

import numpy as np

from motion import canonical as C
from motion import retarget
from motion import rotations as R
from motion.loops import local_poses
from motion.skeleton import Motion

REST_SHARE = 0.04  # of body height: mean joint distance a reference frame lies within
JUMP_STEPS = 8.0  # median steps: the least jump from the last reference frame to motion
JUMP_OVER_NEXT = 3.0  # ... and that many times the step after it (one jump, not fast motion)
MAX_REFERENCE = 4  # frames: a longer run near a rest pose is motion (a T-pose held)


def _about_hips(motion: Motion) -> np.ndarray:
    """:func:`local_poses` with the hips' height taken out too (a rest pose puts them at
    the origin)."""
    local = local_poses(motion)
    return local - local[:, :1] * np.array([0.0, 1.0, 0.0])


def t_pose() -> Motion:
    """The canonical T-pose, one frame."""
    return Motion(C.SKELETON, C.FPS, R.identity((1, len(C.JOINTS))), C.OFFSETS[None].copy())


def rest_on_canonical(rig: retarget.Rig, fps: float) -> Motion:
    """The rest pose of ``rig``'s skeleton (every rotation zero), one frame on the
    canonical skeleton."""
    sk = rig.skeleton
    rest = Motion(sk, fps, R.identity((1, sk.num_joints)), rig.bone_vectors[None].copy())
    return retarget.to_canonical(rest, rig, fps=None)


def leading_reference_frames(motion: Motion, rest: Motion | None = None) -> int:
    """How many of a canonical ``motion``'s first frames are reference frames: each within
    :data:`REST_SHARE` of body height of ``rest`` (the rig's rest pose on the canonical
    skeleton, one frame) or of the T-pose, at most :data:`MAX_REFERENCE`, the last followed
    by a jump of at least :data:`JUMP_STEPS` median steps and :data:`JUMP_OVER_NEXT` times
    the step after it; 0 when not so."""
    if motion.num_frames < MAX_REFERENCE + 4:
        return 0
    head = _about_hips(motion.slice(0, MAX_REFERENCE + 1))
    templates = [t_pose()] + ([rest] if rest is not None else [])
    distance = np.min(
        [np.linalg.norm(head - _about_hips(t)[0], axis=-1).mean(axis=-1) for t in templates],
        axis=0,
    )
    near = distance <= REST_SHARE * C.body_height()
    count = int(np.argmin(near)) if not near.all() else len(near)
    if count == 0 or count > MAX_REFERENCE:
        return 0
    local = local_poses(motion)
    steps = np.linalg.norm(np.diff(local, axis=0), axis=-1).mean(axis=-1)
    jump, following = steps[count - 1], steps[count]
    ordinary = float(np.median(steps[count:]))
    return count if jump >= JUMP_STEPS * ordinary and jump >= JUMP_OVER_NEXT * following else 0

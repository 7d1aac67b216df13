"""Numpy-only motion core: BVH I/O, skeletons, kinematics, retargeting, contacts, IK,
2D keypoints and audio features. Never imports torch.

Conventions used everywhere in this package:
- quaternions are scipy's order ``(x, y, z, w)``, arrays of shape ``(..., 4)``;
- ``lrot``/``lpos`` are local (parent-relative) rotations/translations,
  ``grot``/``gpos`` global ones; clips are ``(F, J, ...)`` (frames, joints);
- Y is up; the canonical character faces +Z.
"""

from motion.errors import MotionError

__all__ = ["MotionError"]

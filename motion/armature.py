"""A Blender armature (as bpy hands it over: bone matrices in armature space, Z up) to a
:class:`~motion.skeleton.Motion` and back, so that an FBX file Blender imports reads like
a BVH of it and a result can be keyed onto its bones again.

An :class:`Armature` is what Blender calls the rest pose: each bone's ``matrix_local``
(head at the translation, the bone along its Y axis), its tail, and the armature object's
world matrix. The motion is the bones' evaluated pose matrices per frame (and the object's
world matrix per frame, folded into the root). As :mod:`motion.gltf` does, each joint is
re-expressed in a frame that the rest pose leaves aligned with the world, the world is
turned Y up (Blender's Z up: ``(x, y, z) -> (x, z, -y)``, what Blender's glTF exporter
does), and leaf bones end at their tails (End Sites). An armature with several root bones
gets the armature object itself as its root joint (named after the object).

:func:`pose_matrices` inverts it: a motion on the armature's joints -> each bone's
armature-space matrix; :func:`to_basis`, each bone's ``matrix_basis`` (location and
quaternion, w first as Blender keys them), for bones that inherit rotation and scale
(Blender's defaults, which its FBX importer keeps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion, Skeleton

# Blender's Z-up world -> the Y-up world of BVH and glTF
Z_UP_TO_Y_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


@dataclass(frozen=True, eq=False)
class Armature:
    """Bones parents first: ``names``, ``parents`` (-1 for a root bone), ``rest`` (J, 4, 4)
    ``matrix_local`` in armature space, ``tails`` (J, 3) in armature space; the object's
    ``name`` and rest ``matrix_world`` (4, 4, uniform scale at most)."""

    name: str
    names: tuple[str, ...]
    parents: np.ndarray
    rest: np.ndarray
    tails: np.ndarray
    matrix_world: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.names)
        parents = np.asarray(self.parents, dtype=np.int64)
        if n == 0:
            raise MotionError("the armature has no bones", kind="unusable")
        if parents.shape != (n,) or any(p >= j for j, p in enumerate(parents)):
            raise MotionError("the armature's bones must be ordered parents first")
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "rest", np.asarray(self.rest, dtype=np.float64))
        object.__setattr__(self, "tails", np.asarray(self.tails, dtype=np.float64))
        object.__setattr__(self, "matrix_world", np.asarray(self.matrix_world, np.float64))
        if self.rest.shape != (n, 4, 4) or self.tails.shape != (n, 3):
            raise MotionError("the armature's rest arrays disagree on the number of bones")
        if self.matrix_world.shape != (4, 4) or not np.isfinite(self.matrix_world).all():
            raise MotionError("the armature object's matrix is not a finite 4x4 matrix")
        _rotation_and_scale(self.matrix_world[:3, :3], "the armature object")

    @property
    def object_root(self) -> bool:
        """Whether the object is the root joint (the armature has several root bones)."""
        return int(np.sum(self.parents < 0)) > 1

    def joint_names(self) -> tuple[str, ...]:
        return ((self.name,) if self.object_root else ()) + self.names


def _rotation_and_scale(m: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """A 3x3 matrix's rotation (its columns normalised) and column scales; a mirroring or
    degenerate matrix is refused."""
    scale = np.linalg.norm(m, axis=-2)
    if (scale < 1e-12).any() or (np.linalg.det(m) <= 0).any():
        raise MotionError(f"{what} is degenerate or mirrored", kind="unusable")
    return m / scale[..., None, :], scale


def _world(armature: Armature, bones: np.ndarray, objects: np.ndarray):
    """World rotations ``(F, J', 3, 3)`` and heads ``(F, J', 3)`` (Y up) of the joints, the
    object first where it is the root joint, from armature-space bone matrices ``bones``
    ``(F, J, 4, 4)`` and object matrices ``objects`` ``(F, 4, 4)``."""
    world = objects[:, None] @ bones
    if armature.object_root:
        world = np.concatenate([objects[:, None], world], axis=1)
    rotm, _ = _rotation_and_scale(world[..., :3, :3], "a bone's or the object's matrix")
    return Z_UP_TO_Y_UP @ rotm, world[..., :3, 3] @ Z_UP_TO_Y_UP.T


def skeleton(armature: Armature) -> Skeleton:
    """The armature's rest pose as a skeleton: offsets between the heads in the Y-up world,
    every joint with position channels (bones may be keyed to move), End Sites at the
    leaf bones' tails."""
    _, heads = _world(armature, armature.rest[None], armature.matrix_world[None])
    heads = heads[0]
    parents = _joint_parents(armature)
    offsets = heads - np.where((parents < 0)[:, None], 0.0, heads[np.maximum(parents, 0)])
    tails = (armature.tails @ armature.matrix_world[:3, :3].T) + armature.matrix_world[:3, 3]
    tails = tails @ Z_UP_TO_Y_UP.T
    shift = 1 if armature.object_root else 0
    has_children = set(parents[parents >= 0].tolist())
    end_sites = {
        j + shift: (tuple(float(v) for v in tails[j] - heads[j + shift]),)
        for j in range(len(armature.names))
        if j + shift not in has_children
    }
    channels = (("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),)
    return Skeleton(armature.joint_names(), parents, offsets, channels * len(parents), end_sites)


def _joint_parents(armature: Armature) -> np.ndarray:
    if not armature.object_root:
        return armature.parents
    return np.concatenate([[-1], np.where(armature.parents < 0, 0, armature.parents + 1)])


def to_motion(
    armature: Armature, bones: np.ndarray, objects: np.ndarray | None, fps: float
) -> Motion:
    """The motion of armature-space bone matrices ``bones`` ``(F, J, 4, 4)`` (Blender's
    ``pose.bones[...].matrix``, frame by frame) with the object at ``objects`` ``(F, 4, 4)``
    (None: at rest), at ``fps`` frames per second."""
    bones = np.asarray(bones, dtype=np.float64)
    if bones.ndim != 4 or bones.shape[1:] != (len(armature.names), 4, 4) or not len(bones):
        raise MotionError(f"bone matrices must be (frames, {len(armature.names)}, 4, 4)")
    if objects is None:
        objects = np.repeat(armature.matrix_world[None], len(bones), axis=0)
    objects = np.asarray(objects, dtype=np.float64)
    if not (np.isfinite(bones).all() and np.isfinite(objects).all()):
        raise MotionError("the armature's animation holds values that are not finite")
    skel = skeleton(armature)
    rest_rot, _ = _world(armature, armature.rest[None], armature.matrix_world[None])
    rot_w, heads = _world(armature, bones, objects)
    grot = rot.from_matrix(rot_w @ np.swapaxes(rest_rot, -1, -2))  # world-aligned frames
    parents = skel.parents
    lrot = K.local_from_global(grot, parents)
    lpos = heads.copy()
    child = parents >= 0
    rel = heads[:, child] - heads[:, parents[child]]
    lpos[:, child] = rot.apply(rot.inv(grot[:, parents[child]]), rel)
    return Motion(skel, float(fps), rot.normalize(lrot), lpos)


def pose_matrices(armature: Armature, motion: Motion) -> np.ndarray:
    """Each bone's armature-space matrix ``(F, J, 4, 4)`` (Blender's ``pose.bones[...].matrix``)
    that plays ``motion`` (on the armature's joints, as :func:`to_motion` reads them) with the
    object left at its rest matrix."""
    names = armature.joint_names()
    if tuple(motion.skeleton.names) != names:
        raise MotionError("the motion is not on the armature's joints", kind="unusable")
    grot, heads = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    rest_rot, _ = _world(armature, armature.rest[None], armature.matrix_world[None])
    rot_w = rot.to_matrix(grot) @ rest_rot  # (F, J', 3, 3) world, Y up
    obj_rot, obj_scale = _rotation_and_scale(armature.matrix_world[:3, :3], "the object")
    to_armature = obj_rot.T @ Z_UP_TO_Y_UP.T
    pose = np.zeros(rot_w.shape[:2] + (4, 4))
    pose[..., :3, :3] = to_armature @ rot_w
    pose[..., :3, 3] = ((heads @ Z_UP_TO_Y_UP) - armature.matrix_world[:3, 3]) @ obj_rot
    pose[..., :3, 3] /= obj_scale
    pose[..., 3, 3] = 1.0
    return pose[:, 1:] if armature.object_root else pose


def to_basis(armature: Armature, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """``(location (F, J, 3), rotation (F, J, 4) w x y z)``: each bone's ``matrix_basis``
    that plays ``motion`` (on the armature's joints, as :func:`to_motion` reads them) with
    the object left at its rest matrix."""
    pose = pose_matrices(armature, motion)
    rest = armature.rest
    parents = armature.parents
    # basis = rest_b^-1 rest_p pose_p^-1 pose_b (a root bone: rest_b^-1 pose_b)
    parent_space = np.where(
        (parents < 0)[None, :, None, None],
        pose,
        _rigid_inverse(pose[:, np.maximum(parents, 0)]) @ pose,
    )
    rel_rest = np.where(
        (parents < 0)[:, None, None],
        _rigid_inverse(rest),
        _rigid_inverse(rest) @ rest[np.maximum(parents, 0)],
    )
    basis = rel_rest[None] @ parent_space
    quat = rot.make_continuous(rot.from_matrix(basis[..., :3, :3]))
    return basis[..., :3, 3], np.concatenate([quat[..., 3:], quat[..., :3]], axis=-1)


def _rigid_inverse(m: np.ndarray) -> np.ndarray:
    out = np.zeros_like(m)
    rt = np.swapaxes(m[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -(rt @ m[..., :3, 3:])[..., 0]
    out[..., 3, 3] = 1.0
    return out

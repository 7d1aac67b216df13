"""motion.armature: Blender's armature matrices to a Motion and back, checked against
Blender's own pose formula (``pose = parent_pose @ parent_rest^-1 @ rest @ basis``) on
rigs built here; the same code on files Blender made is in tests/api/test_fbx_api.py."""

from __future__ import annotations

import numpy as np
import pytest

from motion import armature as A
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError

RNG = np.random.default_rng(7)


def rigid(q_xyzw: np.ndarray, t: np.ndarray) -> np.ndarray:
    m = np.zeros(q_xyzw.shape[:-1] + (4, 4))
    m[..., :3, :3] = rot.to_matrix(q_xyzw)
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def random_quats(shape) -> np.ndarray:
    return rot.normalize(RNG.normal(size=shape + (4,)))


def make_armature(parents, *, matrix_world=None, name="Armature") -> A.Armature:
    """Bones with random rest orientations; each head 1 unit from its parent's along a
    random direction, tails 0.5 along each bone's Y axis."""
    parents = np.asarray(parents)
    n = len(parents)
    rest = rigid(random_quats((n,)), np.zeros((n, 3)))
    for j, p in enumerate(parents):
        if p >= 0:
            rest[j, :3, 3] = rest[p, :3, 3] + RNG.normal(size=3)
    tails = rest[:, :3, 3] + 0.5 * rest[:, :3, 1]
    names = tuple(f"bone{j}" for j in range(n))
    world = np.eye(4) if matrix_world is None else matrix_world
    return A.Armature(name, names, parents, rest, tails, world)


def blender_pose(arm: A.Armature, location: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    """Armature-space pose matrices as Blender evaluates them from ``matrix_basis``."""
    basis = rigid(np.concatenate([quat_wxyz[..., 1:], quat_wxyz[..., :1]], -1), location)
    pose = np.empty_like(basis)
    for j, p in enumerate(arm.parents):
        if p < 0:
            pose[:, j] = arm.rest[j] @ basis[:, j]
        else:
            pose[:, j] = pose[:, p] @ np.linalg.inv(arm.rest[p]) @ arm.rest[j] @ basis[:, j]
    return pose


def random_basis(frames: int, bones: int):
    loc = RNG.normal(scale=0.2, size=(frames, bones, 3))
    q = random_quats((frames, bones))
    q = np.where(q[..., 3:] < 0, -q, q)  # w >= 0, as make_continuous leaves a first frame
    return loc, np.concatenate([q[..., 3:], q[..., :3]], -1)


def object_matrix(scale: float) -> np.ndarray:
    m = rigid(rot.from_euler(np.array([90.0, 0.0, 30.0]), "XYZ"), np.array([1.0, 2.0, 3.0]))
    m[:3, :3] *= scale
    return m


@pytest.mark.parametrize("scale", [1.0, 0.01])
def test_rest_pose_reads_as_identity_rotations_at_the_heads(scale):
    arm = make_armature([-1, 0, 1, 1, 3], matrix_world=object_matrix(scale))
    motion = A.to_motion(arm, arm.rest[None], None, 30.0)
    assert np.allclose(motion.lrot, rot.identity((1, 5)), atol=1e-9)
    heads = (arm.rest[:, :3, 3] @ arm.matrix_world[:3, :3].T + arm.matrix_world[:3, 3]) @ (
        A.Z_UP_TO_Y_UP.T
    )
    assert np.allclose(K.global_positions(motion)[0], heads, atol=1e-9)
    assert np.allclose(motion.skeleton.rest_positions() + heads[0], heads, atol=1e-9)
    # Blender's Z up is the motion's Y up
    up = np.array([0.0, 0.0, 1.0]) @ A.Z_UP_TO_Y_UP.T
    assert np.allclose(up, [0, 1, 0])


@pytest.mark.parametrize("scale", [1.0, 0.01])
@pytest.mark.parametrize("parents", [[-1, 0, 1, 1, 3], [-1, 0, -1, 2, 2]])
def test_basis_round_trips_through_the_motion(parents, scale):
    arm = make_armature(parents, matrix_world=object_matrix(scale))
    loc, quat = random_basis(6, len(parents))
    motion = A.to_motion(arm, blender_pose(arm, loc, quat), None, 24.0)
    assert motion.fps == 24.0 and motion.num_frames == 6
    assert motion.skeleton.names == arm.joint_names()
    back_loc, back_quat = A.to_basis(arm, motion)
    assert np.allclose(back_loc, loc, atol=1e-9)
    same = np.abs(np.sum(back_quat * quat, axis=-1))
    assert np.allclose(same, 1.0, atol=1e-9)


def test_several_root_bones_hang_below_the_object():
    arm = make_armature([-1, 0, -1, 2], name="Rig")
    assert arm.object_root
    skel = A.skeleton(arm)
    assert skel.names == ("Rig", "bone0", "bone1", "bone2", "bone3")
    assert skel.parents.tolist() == [-1, 0, 1, 0, 3]
    assert set(skel.end_sites) == {2, 4}  # the leaf bones end at their tails


def test_object_motion_is_folded_into_the_root():
    arm = make_armature([-1, 0, 1])
    loc, quat = random_basis(3, 3)
    pose = blender_pose(arm, loc, quat)
    moved = np.repeat(np.eye(4)[None], 3, axis=0)
    moved[:, :3, 3] = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]  # the object walks along Blender's X
    still = K.global_positions(A.to_motion(arm, pose, None, 30.0))
    walking = K.global_positions(A.to_motion(arm, pose, moved, 30.0))
    assert np.allclose(walking - still, moved[:, None, :3, 3] @ A.Z_UP_TO_Y_UP.T)


def test_a_motion_on_other_joints_is_refused():
    arm = make_armature([-1, 0, 1])
    other = make_armature([-1, 0, 1, 2])
    motion = A.to_motion(other, other.rest[None], None, 30.0)
    with pytest.raises(MotionError, match="not on the armature's joints"):
        A.to_basis(arm, motion)


def test_a_mirrored_object_is_refused():
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    with pytest.raises(MotionError, match="mirrored"):
        make_armature([-1, 0], matrix_world=mirror)

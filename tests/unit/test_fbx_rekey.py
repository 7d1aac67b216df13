"""A new animation keyed straight into an FBX file's bytes (motion.fbx_rekey, on
motion.fbx_binary): FBX's transform composed and solved back in every rotation order, and,
with Blender as a Python module, Blender's own files rewritten byte for byte outside their
bones' curves, read back by Blender's importer as the motion that was written; a file the
check refuses is exported by Blender instead."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion import armature as A
from motion import fbx_binary as B
from motion import fbx_rekey as R
from motion import kinematics as K
from motion.skeleton import Motion
from tests.fbx_files import make_fbx_files, require_bpy
from tests.rigs import FIXTURE


def model(order: int, active: bool = True, **vectors) -> B.Node:
    props = [
        B.Node.make(
            b"P", name.replace("_", " ").encode(), b"Vector3D", b"Vector", b"", *map(float, value)
        )
        for name, value in vectors.items()
    ]
    props += [
        B.Node.make(b"P", b"RotationOrder", b"enum", b"", b"", B.Int32(order)),
        B.Node.make(b"P", b"RotationActive", b"bool", b"", b"", B.Int32(int(active))),
    ]
    return B.Node.make(
        b"Model",
        7,
        b"bone\x00\x01Model",
        b"LimbNode",
        children=[B.Node.make(b"Properties70", children=props)],
    )


@pytest.mark.parametrize("order", range(6))
def test_solved_translation_and_euler_angles_compose_to_the_local_matrix(order):
    node = R._Node.of(
        model(
            order,
            PreRotation=(-90, 10, 0),
            PostRotation=(0, 30, 5),
            RotationPivot=(1, 2, 3),
            RotationOffset=(0.5, 0, 0),
            ScalingPivot=(0, 1, 0),
        ),
        {},
    )
    rng = np.random.default_rng(order)
    frames = 50
    # a turn of 170 degrees about the sequence's middle axis (tilted a little): past the
    # middle angle's +-90 degrees, where the other set of angles takes over
    axis = np.eye(3)["xyz".index(R._ORDERS[order][1])] + np.array([3e-3, 2e-3, 1e-3])
    turn = np.radians(np.linspace(0, 170, frames))[:, None] * axis / np.linalg.norm(axis)
    local = np.zeros((frames, 1, 4, 4))
    local[:, 0, :3, :3] = Rotation.from_rotvec(turn).as_matrix()
    local[:, 0, :3, 3] = rng.normal(size=(frames, 3))
    local[:, 0, 3, 3] = 1.0
    translation, euler = R._solve([node], local)
    composed = node.matrix(translation[:, 0], euler[:, 0])
    assert np.abs(composed - local[:, 0]).max() < 1e-9
    # continuous: no flip of the other two angles by 180 degrees where the middle one passes
    # 90, as angles only unwrapped by 360 degrees do (near the pole they still run fast)
    plain = R._Node.of(model(order), {})
    _, euler = R._solve([plain], local)
    assert np.abs(np.diff(euler[:, 0], axis=0)).max() < 90.0
    unwrapped = np.unwrap(
        Rotation.from_matrix(local[:, 0, :3, :3]).as_euler(R._ORDERS[order]), axis=0
    )
    assert np.abs(np.degrees(np.diff(unwrapped, axis=0))).max() > 100.0


def test_properties_decode_encode_and_keep_their_type_when_set():
    values = [
        True,
        B.Int16(-3),
        B.Int32(7),
        1 << 40,
        2.5,
        b"name\x00\x01Model",
        np.arange(5, dtype=np.float32),
        np.arange(200, dtype=np.int64),
    ]
    node = B.Node.make(b"X", *values)
    decoded = node.values()
    assert decoded[:6] == values[:6] and all(
        np.array_equal(a, b) for a, b in zip(decoded[6:], values[6:], strict=True)
    )
    kinds = node.raw[0:1]
    node.set(0, False)
    assert node.values()[0] is False and node.raw[0:1] == kinds
    node.set(2, 9)
    assert node.values()[2] == 9 and node.raw[5:6] == b"I"  # after C (2 bytes), Y (3)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("fbx")
    return {
        name: path.read_bytes()
        for name, path in make_fbx_files(FIXTURE, folder).items()
        if name != "character_glb"
    }


def read(data: bytes):
    from service import fbx

    return fbx.read(data, workers=1, timeout=120, max_frames=2000)


def test_a_blender_file_is_parsed_and_written_back_byte_for_byte(files):
    for data in files.values():
        assert B.dumps(B.loads(data)) == data


def kept(data: bytes) -> dict:
    """Every object but animation, with its properties and children's bytes."""

    def flat(node: B.Node) -> tuple:
        return node.name, node.raw, tuple(flat(c) for c in node.children)

    objects = B.loads(data).node(b"Objects").children
    return {o.values()[0]: flat(o) for o in objects if not o.name.startswith(b"Animation")}


@pytest.mark.parametrize("name", ["character", "bare"])
def test_a_new_motion_keyed_into_the_file_is_what_blender_reads_back(files, name):
    require_bpy()
    source = read(files[name])
    plan = R.plan(source.data, source.armature.names, source.armature.parents, source.first_pose)
    assert isinstance(plan, R.Plan), plan
    m = source.motion
    backwards = Motion(m.skeleton, 24.0, m.lrot[::-1].copy(), m.lpos[::-1].copy())
    out = source.write(backwards)
    assert kept(out) == kept(source.data)  # meshes, skin, materials, nodes: the same bytes
    again = read(out)
    assert again.motion.num_frames == m.num_frames and again.motion.fps == pytest.approx(24.0)
    gap = np.abs(K.global_positions(again.motion) - K.global_positions(backwards)).max()
    assert gap < 1e-4 * m.skeleton.height()


def test_a_file_the_check_refuses_is_exported_by_blender_and_still_right(files):
    require_bpy()
    source = read(files["character"])
    first = source.first_pose.copy()
    first[5, :3, 3] += 0.1 * np.abs(first[:, :3, 3]).max()  # not what the file holds
    reason = R.plan(source.data, source.armature.names, source.armature.parents, first)
    assert (
        reason == f"bone {source.armature.names[5]!r}'s FBX transform is not the one Blender read"
    )
    source.first_pose = first
    m = source.motion
    backwards = Motion(m.skeleton, m.fps, m.lrot[::-1].copy(), m.lpos[::-1].copy())
    out = source.write(backwards)
    assert kept(out) != kept(source.data)  # Blender's exporter wrote it anew
    again = read(out)
    gap = np.abs(K.global_positions(again.motion) - K.global_positions(backwards)).max()
    assert gap < 0.01 * m.skeleton.height()
    assert again.motion.num_frames == m.num_frames


def test_pose_matrices_are_what_to_basis_keys(files):
    require_bpy()
    source = read(files["character"])
    pose = A.pose_matrices(source.armature, source.motion)
    assert np.abs(pose[0] - source.first_pose).max() < 1e-4 * np.abs(pose[..., :3, 3]).max()

"""Mapping any humanoid onto the canonical skeleton and back."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh
from motion import canonical as C
from motion import kinematics as K
from motion import retarget as RT
from motion import rotations as rot
from motion.errors import MotionError
from motion.rig_mapping import REQUIRED
from tests import rigs
from tests.conftest import data_path

SHARED_LAYOUTS = [
    ("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh"),
    ("bandai", "dataset-2", "dataset-2_walk_normal_001.bvh"),
    ("cmu-31", "02_01.bvh"),
    ("xia", "angry_13_000.bvh"),
    ("cmu-dance-43", "05_20.bvh"),
    ("cmu-dance-43", "60_01_scaled.bvh"),
    ("cmu-dance-3dsmax", "94_01_indian_dance.bvh"),
]
HAS_TOES = {"bandai", "cmu-31", "xia", "cmu-dance-3dsmax"}


def mapped_positions(motion, rig):
    return K.global_positions(motion)[:, list(rig.mapping.values())]


@pytest.mark.parametrize("parts", SHARED_LAYOUTS, ids=lambda p: "/".join(p))
def test_every_shared_skeleton_maps_fully(parts):
    m = bvh.load(data_path(*parts))
    rig = RT.make_rig(m.skeleton, m)
    assert rig.up_axis == "Y"  # Bandai's rest pose lies along X, yet its world is Y-up
    expected = set(C.JOINTS) - {"joint_Root"}
    if parts[0] not in HAS_TOES:
        expected -= {"Toes_L", "Toes_R"}  # the DAZ layout has no toe joints
    assert expected <= set(rig.mapping), expected - set(rig.mapping)
    # mapped joints are distinct and sides are not swapped: left joints sit on the body's left
    assert len(set(rig.mapping.values())) == len(rig.mapping)
    canon = RT.to_canonical(m, rig)
    g = K.global_positions(canon)
    frame = RT.body_frame(g, C.INDEX)
    hand_l = np.einsum("fji,fj->fi", frame, g[:, C.INDEX["UpperArm_L"]] - g[:, C.INDEX["Chest"]])
    assert np.mean(hand_l[:, 0] > 0) > 0.95


@pytest.mark.parametrize("parts", SHARED_LAYOUTS, ids=lambda p: "/".join(p))
def test_canonical_and_back_reproduces_positions(parts):
    m = bvh.load(data_path(*parts))
    rig = RT.make_rig(m.skeleton, m)
    height = rig.height
    exact = RT.from_canonical(RT.to_canonical(m, rig, fps=None), rig, like=m)
    err = np.abs(mapped_positions(exact, rig) - mapped_positions(m, rig)).max() / height
    assert err < 1e-9
    # the service path: to 30 fps canonical and back to the clip's own rate. Going
    # through 30 fps loses what a 30 fps sampling loses and nothing more.
    back = RT.from_canonical(RT.to_canonical(m, rig), rig, like=m)
    assert back.num_frames == m.num_frames and back.fps == m.fps
    err = np.linalg.norm(mapped_positions(back, rig) - mapped_positions(m, rig), axis=-1)
    own = K.resample_count(K.resample(m, 30.0), m.fps, m.num_frames)
    sampling = np.linalg.norm(mapped_positions(own, rig) - mapped_positions(m, rig), axis=-1)
    assert np.mean(err) / height < 0.01 and np.percentile(err, 95) / height < 0.01
    assert abs(np.percentile(err, 95) - np.percentile(sampling, 95)) / height < 0.001
    # the command line's way (`motion canonical --fps <its fps>`, then `motion retarget
    # --onto` the file): no clip to follow, the joints in between hold their usual pose
    alone = RT.from_canonical(RT.to_canonical(m, rig, fps=None), rig)
    err = np.linalg.norm(mapped_positions(alone, rig) - mapped_positions(m, rig), axis=-1)
    assert np.percentile(err, 95) / height < 0.01, np.percentile(err, 95) / height
    # joints without a canonical counterpart keep their own motion
    used = set(rig.mapping.values())
    for j in range(m.skeleton.num_joints):
        if j not in used and j != 0:
            dot = np.abs(np.sum(back.lrot[:, j] * m.lrot[:, j], axis=-1))
            assert np.all(dot > 1 - 1e-12), m.skeleton.names[j]


def canonical_pose(motion):
    """Root-relative canonical joint positions, and the leg length they are scaled by."""
    canon = RT.to_canonical(motion, fps=None)
    g = K.global_positions(canon)
    return g - g[:, 1:2]


def test_exporter_variants_give_the_same_canonical_motion():
    base = rigs.load_fixture()
    ref = canonical_pose(base)
    height = 175.0
    for name, m in rigs.variants(base).items():
        rig = RT.make_rig(m.skeleton, m)
        assert set(REQUIRED) <= set(rig.mapping), name
        got = canonical_pose(m)
        err = np.linalg.norm(got - ref, axis=-1)
        assert err.max() / height < 0.02, (name, rig.reference, err.max())


def test_variant_mappings_pick_the_right_joints():
    v = rigs.variants(rigs.load_fixture())
    mix = RT.make_rig(v["mixamo_tpose_zxy"].skeleton).mapping_by_name()
    assert mix["Hips"] == "mixamorig:Hips" and mix["Chest"] == "mixamorig:Spine2"
    assert mix["UpperArm_L"] == "mixamorig:LeftArm" and mix["Toes_R"] == "mixamorig:RightToeBase"
    ue = RT.make_rig(
        v["unreal_rotated_frames"].skeleton, v["unreal_rotated_frames"]
    ).mapping_by_name()
    assert ue["Hips"] == "pelvis" and ue["LowerLeg_L"] == "calf_l" and ue["Toes_L"] == "ball_l"
    assert ue["Shoulder_R"] == "clavicle_r" and ue["Head"] == "head" and ue["Neck"] == "neck_02"
    biped = RT.make_rig(v["biped_xyz_6ch"].skeleton).mapping_by_name()
    assert biped["UpperLeg_L"] == "Bip01 L Thigh" and biped["Hand_R"] == "Bip01 R Hand"
    # without a clip the spine joint is the first above the hips (CMU's lower back)
    assert biped["Spine"] == "Bip01 Spine" and biped["Chest"] == "Bip01 Spine2"
    blend = RT.make_rig(v["blender_apose"].skeleton).mapping_by_name()
    assert blend["LowerLeg_L"] == "shin.L" and blend["UpperArm_R"] == "upper_arm.R"


def test_rotated_frames_fall_back_to_a_standing_frame():
    v = rigs.variants(rigs.load_fixture())
    rig = RT.make_rig(v["maya_random_frames_cm"].skeleton, v["maya_random_frames_cm"])
    assert rig.reference.startswith("frame")
    assert RT.make_rig(v["cmu"].skeleton).reference == "rest"
    assert RT.make_rig(v["blender_apose"].skeleton).reference == "rest"


def test_retarget_onto_another_skeleton_keeps_bone_directions():
    src = rigs.load_fixture()
    onto = bvh.load(data_path("bandai", "dataset-1", "dataset-1_bow_normal_001.bvh"))
    out = RT.retarget(src, onto.skeleton)
    assert out.skeleton.names == onto.skeleton.names and out.fps == src.fps
    gs, go = K.global_positions(src), K.global_positions(out)
    s_rig, o_rig = RT.make_rig(src.skeleton, src), RT.make_rig(onto.skeleton, onto)
    for a, b in [
        ("UpperLeg_L", "LowerLeg_L"),
        ("LowerLeg_R", "Foot_R"),
        ("Foot_L", "Toes_L"),
        ("UpperArm_L", "LowerArm_L"),
        ("LowerArm_R", "Hand_R"),
        ("Neck", "Head"),
    ]:
        ds = gs[:, s_rig.mapping[b]] - gs[:, s_rig.mapping[a]]
        do = go[:, o_rig.mapping[b]] - go[:, o_rig.mapping[a]]
        cos = np.sum(ds * do, -1) / np.linalg.norm(ds, axis=-1) / np.linalg.norm(do, axis=-1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1.0, (a, b)
    # root trajectory scaled by leg length
    travel_src = np.ptp(gs[:, 0, [0, 2]], axis=0).max() / s_rig.leg_length
    travel_out = np.ptp(go[:, o_rig.mapping["Hips"], [0, 2]], axis=0).max() / o_rig.leg_length
    assert abs(travel_src - travel_out) / travel_src < 0.01


def test_explicit_mapping_overrides_and_accepts_either_direction():
    m = rigs.renamed(rigs.load_fixture(), {"Head": "skull", "LeftHand": "paw_left"})
    rig = RT.make_rig(m.skeleton, m)  # names miss the head and a hand: structure finds them
    assert rig.method == "structure"
    assert (
        rig.mapping_by_name()["Head"] == "skull" and rig.mapping_by_name()["Hand_L"] == "paw_left"
    )
    rig = RT.make_rig(m.skeleton, mapping={"skull": "Head", "Hand_L": "LeftFingerBase"})
    assert rig.mapping_by_name()["Head"] == "skull"
    assert rig.mapping_by_name()["Hand_L"] == "LeftFingerBase"  # the caller's word wins
    with pytest.raises(MotionError, match="names no canonical joint"):
        RT.make_rig(m.skeleton, mapping={"skull": "NotAJoint"})


def test_non_humanoid_lists_what_it_could_not_find():
    from motion.skeleton import Skeleton

    n = 30  # a snake: one chain, no limbs
    offsets = np.tile([0.0, 0.0, 5.0], (n, 1))
    snake = Skeleton(tuple(f"seg{i}" for i in range(n)), np.arange(n) - 1, offsets)
    with pytest.raises(MotionError) as err:
        RT.make_rig(snake)
    assert err.value.kind == "unusable"
    assert set(err.value.unmapped) == set(REQUIRED)
    assert "by structure" in str(err.value) and "mapping" in str(err.value)


def test_canonical_skeleton_is_a_tpose_facing_z():
    rest = C.SKELETON.rest_positions()
    i = C.INDEX
    assert rest[i["Hand_L"], 0] > 50 and rest[i["Hand_R"], 0] < -50  # arms out along x
    assert abs(rest[i["Hand_L"], 1] - rest[i["UpperArm_L"], 1]) < 1e-9
    assert rest[i["Toes_L"], 2] > rest[i["Foot_L"], 2]  # feet point forward (+z)
    assert abs(min(rest[i["Toes_L"], 1], rest[i["Toes_R"], 1])) < 1e-6  # toes on the floor
    assert RT.make_rig(C.SKELETON).reference == "rest"
    assert np.allclose(np.abs(RT.make_rig(C.SKELETON).tpose[1:, 3]), 1.0, atol=1e-9)


def test_z_up_files_are_turned_upright_and_back():
    y_up = rigs.load_fixture()
    z_up = rigs.z_up(y_up)
    rig = RT.make_rig(z_up.skeleton, z_up)
    assert rig.up_axis == "Z" and rig.reference == "rest"
    assert RT.make_rig(y_up.skeleton, y_up).up_axis == "Y"
    # the canonical motion is the Y-up file's, hips trajectory included
    a = K.global_positions(RT.to_canonical(y_up))
    b = K.global_positions(RT.to_canonical(z_up, rig))
    assert np.abs(a - b).max() < 1e-6 * 175
    # back onto the Z-up skeleton: the file's own world, with and without the clip
    back = RT.from_canonical(RT.to_canonical(z_up, rig, fps=None), rig, like=z_up)
    assert np.abs(K.global_positions(back) - K.global_positions(z_up)).max() < 1e-6 * 175
    pose = K.global_positions(RT.from_canonical(RT.to_canonical(z_up, rig), rig))
    spine = pose[:, rig.mapping["Chest"]] - pose[:, rig.mapping["Hips"]]
    assert np.all(spine[:, 2] > 0.9 * np.linalg.norm(spine, axis=-1))


def test_upright_needs_the_rest_pose_and_the_motion_to_agree():
    # a Y-up clip of someone lying on the floor (the root turned, the rest pose standing)
    m = rigs.load_fixture()
    q = rot.from_rotvec(np.array([np.pi / 2, 0.0, 0.0]))
    lrot, lpos = m.lrot.copy(), m.lpos.copy()
    lrot[:, 0] = rot.mul(q, lrot[:, 0])
    lpos[:, 0] = rot.apply(q, lpos[:, 0])
    lying = m.replace(lrot=lrot, lpos=lpos)
    assert RT.make_rig(lying.skeleton, lying).up_axis == "Y"
    # a Z-up skeleton without a clip: its standing rest pose decides
    assert RT.make_rig(rigs.z_up(m).skeleton).up_axis == "Z"

"""Exporter-style variants of a clip, made by code: each performs exactly the same motion in
world space (same joint positions) but presents it the way another tool would: other joint
names (Mixamo, Unreal, 3ds Max Biped, Blender), rotated joint frames (Maya/Bandai style,
rest pose meaningless), an A-pose rest, an extra root above the hips, other channel orders
and channel counts, Z up, other units. The foreign-content evaluation sends clips this way
(``training.eval_foreign``), and the tests build their rig corpus on them."""

from __future__ import annotations

import numpy as np

from motion import rotations as rot
from motion.skeleton import Motion, Skeleton

CMU_TO_MIXAMO = {
    "Hips": "mixamorig:Hips", "LHipJoint": "mixamorig:LHipJoint", "LeftUpLeg": "mixamorig:LeftUpLeg",
    "LeftLeg": "mixamorig:LeftLeg", "LeftFoot": "mixamorig:LeftFoot",
    "LeftToeBase": "mixamorig:LeftToeBase", "RHipJoint": "mixamorig:RHipJoint",
    "RightUpLeg": "mixamorig:RightUpLeg", "RightLeg": "mixamorig:RightLeg",
    "RightFoot": "mixamorig:RightFoot", "RightToeBase": "mixamorig:RightToeBase",
    "LowerBack": "mixamorig:Spine", "Spine": "mixamorig:Spine1", "Spine1": "mixamorig:Spine2",
    "Neck": "mixamorig:Neck", "Neck1": "mixamorig:Neck1", "Head": "mixamorig:Head",
    "LeftShoulder": "mixamorig:LeftShoulder", "LeftArm": "mixamorig:LeftArm",
    "LeftForeArm": "mixamorig:LeftForeArm", "LeftHand": "mixamorig:LeftHand",
    "RightShoulder": "mixamorig:RightShoulder", "RightArm": "mixamorig:RightArm",
    "RightForeArm": "mixamorig:RightForeArm", "RightHand": "mixamorig:RightHand",
}  # fmt: skip
CMU_TO_UNREAL = {
    "Hips": "pelvis", "LHipJoint": "hip_helper_l", "LeftUpLeg": "thigh_l", "LeftLeg": "calf_l",
    "LeftFoot": "foot_l", "LeftToeBase": "ball_l", "RHipJoint": "hip_helper_r",
    "RightUpLeg": "thigh_r", "RightLeg": "calf_r", "RightFoot": "foot_r", "RightToeBase": "ball_r",
    "LowerBack": "spine_01", "Spine": "spine_02", "Spine1": "spine_03", "Neck": "neck_01",
    "Neck1": "neck_02", "Head": "head", "LeftShoulder": "clavicle_l", "LeftArm": "upperarm_l",
    "LeftForeArm": "lowerarm_l", "LeftHand": "hand_l", "RightShoulder": "clavicle_r",
    "RightArm": "upperarm_r", "RightForeArm": "lowerarm_r", "RightHand": "hand_r",
    "LeftFingerBase": "index_01_l", "LeftHandIndex1": "index_02_l", "LThumb": "thumb_01_l",
    "RightFingerBase": "index_01_r", "RightHandIndex1": "index_02_r", "RThumb": "thumb_01_r",
}  # fmt: skip
CMU_TO_BIPED = {
    "Hips": "Bip01 Pelvis", "LHipJoint": "Bip01 L HipHelper", "LeftUpLeg": "Bip01 L Thigh",
    "LeftLeg": "Bip01 L Calf", "LeftFoot": "Bip01 L Foot", "LeftToeBase": "Bip01 L Toe0",
    "RHipJoint": "Bip01 R HipHelper", "RightUpLeg": "Bip01 R Thigh", "RightLeg": "Bip01 R Calf",
    "RightFoot": "Bip01 R Foot", "RightToeBase": "Bip01 R Toe0", "LowerBack": "Bip01 Spine",
    "Spine": "Bip01 Spine1", "Spine1": "Bip01 Spine2", "Neck": "Bip01 Neck",
    "Neck1": "Bip01 Neck1", "Head": "Bip01 Head", "LeftShoulder": "Bip01 L Clavicle",
    "LeftArm": "Bip01 L UpperArm", "LeftForeArm": "Bip01 L Forearm", "LeftHand": "Bip01 L Hand",
    "RightShoulder": "Bip01 R Clavicle", "RightArm": "Bip01 R UpperArm",
    "RightForeArm": "Bip01 R Forearm", "RightHand": "Bip01 R Hand",
    "LeftFingerBase": "Bip01 L Finger0", "LeftHandIndex1": "Bip01 L Finger01",
    "LThumb": "Bip01 L Finger1", "RightFingerBase": "Bip01 R Finger0",
    "RightHandIndex1": "Bip01 R Finger01", "RThumb": "Bip01 R Finger1",
}  # fmt: skip
CMU_TO_BLENDER = {
    "Hips": "hips", "LHipJoint": "pelvis.L", "LeftUpLeg": "thigh.L", "LeftLeg": "shin.L",
    "LeftFoot": "foot.L", "LeftToeBase": "toe.L", "RHipJoint": "pelvis.R",
    "RightUpLeg": "thigh.R", "RightLeg": "shin.R", "RightFoot": "foot.R", "RightToeBase": "toe.R",
    "LowerBack": "spine", "Spine": "spine.001", "Spine1": "chest", "Neck": "neck",
    "Neck1": "neck.001", "Head": "head", "LeftShoulder": "shoulder.L", "LeftArm": "upper_arm.L",
    "LeftForeArm": "forearm.L", "LeftHand": "hand.L", "RightShoulder": "shoulder.R",
    "RightArm": "upper_arm.R", "RightForeArm": "forearm.R", "RightHand": "hand.R",
}  # fmt: skip


def renamed(motion: Motion, names: dict[str, str]) -> Motion:
    sk = motion.skeleton
    new = tuple(names.get(n, n) for n in sk.names)
    return motion.replace(skeleton=Skeleton(new, sk.parents, sk.offsets, sk.channels, sk.end_sites))


def reframed(motion: Motion, frames: np.ndarray) -> Motion:
    """Same world motion with each joint's local frame turned by ``frames (J, 4)``.

    Offsets are re-expressed in the turned parent frames, so the rest pose (all
    rotations zero) changes while every frame's joint positions stay the same.
    """
    sk = motion.skeleton
    q = rot.normalize(frames)
    par = sk.parents
    qp = np.where((par >= 0)[:, None], q[np.maximum(par, 0)], rot.IDENTITY)
    offsets = rot.apply(rot.inv(qp), sk.offsets)
    offsets[0] = sk.offsets[0]
    lrot = rot.mul(rot.inv(qp)[None], rot.mul(motion.lrot, q[None]))
    lpos = rot.apply(rot.inv(qp)[None], motion.lpos)
    lpos[:, 0] = motion.lpos[:, 0]
    end_sites = {
        j: tuple(tuple(rot.apply(rot.inv(q[j]), np.array(o))) for o in offs)
        for j, offs in sk.end_sites.items()
    }
    new_sk = Skeleton(sk.names, sk.parents, offsets, sk.channels, end_sites)
    return Motion(new_sk, motion.fps, lrot, lpos)


def random_frames(motion: Motion, seed: int = 0) -> Motion:
    """Maya/Bandai style: every joint frame turned by a random rotation."""
    rng = np.random.default_rng(seed)
    return reframed(motion, rot.normalize(rng.normal(size=(motion.skeleton.num_joints, 4))))


def a_pose(motion: Motion) -> Motion:
    """Rest pose with the arms 45 degrees down (the world motion unchanged)."""
    sk = motion.skeleton
    frames = rot.identity((sk.num_joints,))
    for name, sign in (("LeftArm", 1.0), ("RightArm", -1.0)):
        if name in sk.names:
            # offsets of children are expressed in the turned frame: turning the frame
            # up by 45 degrees makes the rest arm point 45 degrees down
            frames[sk.names.index(name)] = rot.from_rotvec(np.array([0.0, 0.0, sign * np.pi / 4]))
    return reframed(motion, frames)


def with_extra_root(motion: Motion, name: str = "root") -> Motion:
    """An unanimated root joint above the hips, as Unreal exports have."""
    sk = motion.skeleton
    parents = np.concatenate([[-1], sk.parents + 1])
    parents[1] = 0
    offsets = np.concatenate([np.zeros((1, 3)), sk.offsets])
    chans = (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),)
    new_sk = Skeleton(
        (name,) + sk.names,
        parents,
        offsets,
        chans + sk.channels,
        {j + 1: v for j, v in sk.end_sites.items()},
    )
    frames = motion.num_frames
    lrot = np.concatenate([rot.identity((frames, 1)), motion.lrot], axis=1)
    lpos = np.concatenate([np.zeros((frames, 1, 3)), motion.lpos], axis=1)
    return Motion(new_sk, motion.fps, lrot, lpos)


def with_channels(motion: Motion, order: str = "XYZ", positions_everywhere: bool = False) -> Motion:
    """Another Euler order on every joint (and optionally 6 channels on all joints)."""
    sk = motion.skeleton
    rot_ch = tuple(f"{a}rotation" for a in order)
    chans = []
    for j in range(sk.num_joints):
        has_pos = j == 0 or positions_everywhere
        chans.append((("Xposition", "Yposition", "Zposition") if has_pos else ()) + rot_ch)
    new_sk = Skeleton(sk.names, sk.parents, sk.offsets, tuple(chans), sk.end_sites)
    return motion.replace(skeleton=new_sk)


def with_animated_translations(motion: Motion, seed: int = 0) -> Motion:
    """Position channels on every joint whose values are not the OFFSETs, as markerless
    capture exporters (Brekel's) write them: each bone's vector in its parent's frame is
    the offset turned by up to 0.15 radians and its length off by up to 6% (the solver's
    skeleton against the file's template), and it keeps moving by 0.02 radians and 1% of
    its length (about 1 Hz, each bone its own phase). Rotations are ``motion``'s."""
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    joints = sk.num_joints
    t = np.arange(motion.num_frames)[:, None] / motion.fps
    phase = rng.uniform(0, 2 * np.pi, size=(3, joints))
    rate = rng.uniform(0.6, 1.4, size=(3, joints))
    wave = np.sin(2 * np.pi * rate[:, None] * t[None] + phase[:, None])  # (3, F, J)
    turn = rng.uniform(-0.15, 0.15, size=(joints, 3)) * [1.0, 1.0, 0.0]
    stretch = rng.uniform(0.94, 1.06, size=joints)
    moving = 0.02 * np.stack([wave[0], wave[1], np.zeros_like(wave[0])], -1)
    swing = rot.mul(rot.from_rotvec(moving), rot.from_rotvec(turn)[None])
    lpos = rot.apply(swing, sk.offsets[None]) * (stretch * (1.0 + 0.01 * wave[2]))[..., None]
    lpos[:, 0] = motion.lpos[:, 0]
    return with_channels(motion, positions_everywhere=True).replace(lpos=lpos)


def scaled(motion: Motion, factor: float) -> Motion:
    sk = motion.skeleton
    new_sk = Skeleton(
        sk.names,
        sk.parents,
        sk.offsets * factor,
        sk.channels,
        {j: tuple(tuple(np.array(o) * factor) for o in offs) for j, offs in sk.end_sites.items()},
    )
    return Motion(new_sk, motion.fps, motion.lrot, motion.lpos * factor)


def z_up(motion: Motion) -> Motion:
    """The same performance in a Z-up world (3ds Max, Blender): rest pose and motion turned
    +90 degrees about X, every local frame with them, so the file stands along Z."""
    q = rot.from_rotvec(np.array([np.pi / 2, 0.0, 0.0]))
    sk = motion.skeleton
    end_sites = {
        j: tuple(tuple(rot.apply(q, np.array(o))) for o in offs) for j, offs in sk.end_sites.items()
    }
    new_sk = Skeleton(sk.names, sk.parents, rot.apply(q, sk.offsets), sk.channels, end_sites)
    lrot = rot.mul(q, rot.mul(motion.lrot, rot.inv(q)))
    return Motion(new_sk, motion.fps, lrot, rot.apply(q, motion.lpos))


def variants(motion: Motion) -> dict[str, Motion]:
    """Every exporter-style presentation of ``motion`` the tests run through."""
    return {
        "cmu": motion,
        "mixamo_tpose_zxy": with_channels(renamed(motion, CMU_TO_MIXAMO), "ZXY"),
        "unreal_rotated_frames": with_extra_root(random_frames(renamed(motion, CMU_TO_UNREAL), 1)),
        "biped_xyz_6ch": with_channels(
            renamed(motion, CMU_TO_BIPED), "XYZ", positions_everywhere=True
        ),
        "blender_apose": renamed(a_pose(motion), CMU_TO_BLENDER),
        "maya_random_frames_cm": scaled(random_frames(motion, 7), 5.6),
        "max_biped_z_up": z_up(renamed(motion, CMU_TO_BIPED)),
    }

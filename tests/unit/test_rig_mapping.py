"""Which joint is which: naming conventions, the structural reading, confidence, refusal."""

from __future__ import annotations

import time

import numpy as np
import pytest

from motion import bvh, rig_names
from motion import retarget as RT
from motion import rig_mapping as RM
from motion import rotations as rot
from motion.errors import AmbiguousRigError, MotionError
from motion.skeleton import Motion, Skeleton
from tests import rigs
from tests.conftest import DATA_DIR

CONVENTION_LABELS = {
    "Reallusion CC/iClone": "Reallusion CC/iClone",
    "Maya _JNT": "Maya _JNT",
    "MB-Lab": "Unreal / MB-Lab",
    "Kinect v2": "Kinect v2",
    "Xsens MVN": "Xsens MVN",
    "Second Life (Bento)": "Second Life (Bento)",
    "VRoid (VRM)": "VRoid (VRM)",
    "Daz Genesis 8": "Daz Genesis 8",
    "Daz Genesis 9": "Daz Genesis 9",
    "OptiTrack Motive": "OptiTrack Motive",
    "Vicon Plug-in Gait": "Vicon Plug-in Gait",
    "Unity humanoid": "Unity humanoid / VRM",
}


@pytest.fixture(scope="module")
def conventions() -> dict[str, rigs.CorpusRig]:
    fixture = rigs.load_fixture()
    return {name: rigs.convention_rig(fixture, name) for name in rigs.CONVENTION_RIGS}


@pytest.mark.parametrize("convention", sorted(CONVENTION_LABELS))
def test_conventions_are_known_by_name(conventions, convention):
    item = conventions[convention]
    found = RM.find_mapping(item.motion.skeleton, item.motion)
    assert found.method == "names" and found.convention == CONVENTION_LABELS[convention]
    assert set(RM.REQUIRED) <= set(found.joints)
    assert found.confidence >= 0.9
    names = item.motion.skeleton.names
    for joint in RM.REQUIRED:  # each copies the fixture joint CMU's names map there
        origin = item.origin.get(names[found.joints[joint]])
        if origin is not None:
            want = RT.make_rig(item.source.skeleton, item.source).mapping_by_name()[joint]
            assert origin == want, (joint, names[found.joints[joint]], origin, want)


def test_the_issues_rigs_map_where_they_failed(conventions):
    """A Reallusion rig (Hip above Pelvis with the legs and Waist with the spine) and a
    Maya _JNT rig with l_/r_ prefixes were refused: "not below the hips", "no joint found"."""
    cc = conventions["Reallusion CC/iClone"].motion
    m = RT.make_rig(cc.skeleton, cc).mapping_by_name()
    assert m["Hips"] == "CC_Base_Hip" and m["LowerArm_L"] == "CC_Base_L_Forearm"
    assert m["UpperLeg_R"] == "CC_Base_R_Thigh" and m["Head"] == "CC_Base_Head"
    jnt = conventions["Maya _JNT"].motion
    m = RT.make_rig(jnt.skeleton, jnt).mapping_by_name()
    assert m["Hips"] == "hips_JNT" and m["UpperLeg_L"] == "l_upleg_JNT"
    assert m["LowerArm_L"] == "l_forearm_JNT" and m["Chest"] == "spine2_JNT"
    kinect = conventions["Kinect v2"].motion
    m = RT.make_rig(kinect.skeleton, kinect).mapping_by_name()
    assert m["UpperArm_L"] == "ShoulderLeft" and m["Hand_L"] == "WristLeft"
    assert m["Toes_R"] == "FootRight" and m["Hips"] == "SpineBase" and "Shoulder_L" not in m


def test_a_convention_is_found_behind_any_common_prefix():
    names = tuple(f"Actor7:{n}" for n in ("Hip", "Ab", "Chest", "Neck", "Head", "LThigh",
                  "LShin", "LFoot", "RThigh", "RShin", "RFoot", "LShoulder", "LUArm", "LFArm",
                  "LHand", "RShoulder", "RUArm", "RFArm", "RHand"))  # fmt: skip
    convention, found = rig_names.match_convention(names)
    assert convention == "OptiTrack Motive"
    assert names[found["UpperArm_R"]] == "Actor7:RUArm" and names[found["Hips"]] == "Actor7:Hip"


def test_names_are_normalised_for_decorations_and_sides():
    assert rig_names.normalise_name("l_upleg_JNT") == ("L", "upleg")
    assert rig_names.normalise_name("CC_Base_R_Forearm") == ("R", "forearm")
    assert rig_names.normalise_name("mixamorig:LeftHand") == ("L", "hand")
    assert rig_names.normalise_name("thigh.R") == ("R", "thigh")
    assert rig_names.is_helper("CC_Base_L_UpperarmTwist01") and rig_names.is_helper("weapon_r")
    assert not rig_names.is_helper("l_forearm_JNT")


def featureless(motion: Motion) -> Motion:
    """The fixture's rest pose as a one-frame clip with numbered joints, no toes and feet
    ending straight down: nothing says which way it faces."""
    sk = motion.skeleton
    keep = [j for j, n in enumerate(sk.names) if "Toe" not in n]
    index = {old: new for new, old in enumerate(keep)}
    parents = np.array([-1 if sk.parents[j] < 0 else index[int(sk.parents[j])] for j in keep])
    ends = {index[j]: v for j, v in sk.end_sites.items() if j in index}
    for j in keep:
        if sk.names[j] in ("LeftFoot", "RightFoot"):
            ends[index[j]] = ((0.0, -0.5, 0.0),)
    names = tuple(f"bone{i:02d}" for i in range(len(keep)))
    new = Skeleton(names, parents, sk.offsets[keep], tuple(sk.channels[j] for j in keep), ends)
    lpos = sk.offsets[keep][None].copy()
    lpos[0, 0] = [0.0, 17.0, 0.0]
    return Motion(new, 30.0, rot.identity((1, len(keep))), lpos)


def test_a_rig_whose_sides_nothing_tells_apart_is_refused_with_a_way_out():
    still = featureless(rigs.load_fixture())
    with pytest.raises(AmbiguousRigError) as err:
        RT.make_rig(still.skeleton, still)
    e = err.value
    assert e.kind == "unusable" and isinstance(e, MotionError)
    details = e.details()
    assert {c["limbs"] for c in details["ambiguous"]} == {"legs", "arms"}
    for pair in details["ambiguous"]:
        assert len(pair["chains"]) == 2 and all(pair["chains"])
    assert "mapping" in details["mapping_help"] and "mapping" in str(e)
    # the example names one side of each pair; passed back, it settles the rig
    example = details["mapping_example"]
    rig = RT.make_rig(still.skeleton, still, mapping=example)
    assert rig.mapping_by_name()["UpperLeg_L"] == example["UpperLeg_L"]
    assert rig.mapping_by_name()["UpperArm_L"] == example["UpperArm_L"]
    # one side is enough: the other pair follows from where the first puts the body's left
    only_legs = {"UpperLeg_L": example["UpperLeg_L"]}
    rig = RT.make_rig(still.skeleton, still, mapping=only_legs)
    left_leg = still.skeleton.rest_positions()[rig.mapping["UpperLeg_L"]]
    left_arm = still.skeleton.rest_positions()[rig.mapping["UpperArm_L"]]
    right_arm = still.skeleton.rest_positions()[rig.mapping["UpperArm_R"]]
    assert np.sign(left_arm[0] - right_arm[0]) == np.sign(left_leg[0])


def test_side_names_settle_what_geometry_cannot():
    still = featureless(rigs.load_fixture())
    fixture = rigs.load_fixture().skeleton.names
    kept = [n for n in fixture if "Toe" not in n]
    sides = tuple(f"{n[0]}_{i:02d}" if n[0] in "LR" and not n.startswith("Low") else b
                  for i, (n, b) in enumerate(zip(kept, still.skeleton.names, strict=True)))  # fmt: skip
    named = still.replace(skeleton=Skeleton(sides, *_rest(still.skeleton)))
    rig = RT.make_rig(named.skeleton, named)
    assert rig.method == "structure"
    assert rig.mapping_by_name()["UpperLeg_L"].startswith("L_")
    assert rig.mapping_by_name()["Hand_R"].startswith("R_")


def _rest(sk: Skeleton):
    return sk.parents, sk.offsets, sk.channels, sk.end_sites


def test_names_that_contradict_the_geometry_lower_the_confidence():
    fixture = rigs.load_fixture()
    swap = {n: n.replace("Left", "Tmp").replace("Right", "Left").replace("Tmp", "Right")
            for n in fixture.skeleton.names}  # fmt: skip
    mirrored = rigs.renamed(fixture, swap)
    assert RT.make_rig(fixture.skeleton, fixture).confidence == 1.0
    assert RT.make_rig(mirrored.skeleton, mirrored).confidence <= 0.3


def test_not_a_humanoid_and_too_many_joints_are_refused_quickly():
    wide = Skeleton(("r",) + tuple(f"j{i}" for i in range(9999)), np.r_[-1, np.zeros(9999, int)],
                    np.tile([0.0, 1.0, 0.0], (10000, 1)))  # fmt: skip
    t0 = time.perf_counter()
    with pytest.raises(MotionError) as err:
        RT.make_rig(wide)
    assert time.perf_counter() - t0 < 5.0
    assert err.value.kind == "unusable" and "too many" in str(err.value)


def every_shared_bvh() -> list[str]:
    if not DATA_DIR.exists():
        return []
    return sorted(str(p.relative_to(DATA_DIR)) for p in DATA_DIR.rglob("*.bvh"))


def head_of(path, frames: int = 90) -> Motion:
    """The file's hierarchy and its first ``frames`` frames (reading all takes long)."""
    text = path.read_text(errors="replace").replace("\r\n", "\n")
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().split("\n")
    rows = [r for r in lines[2:] if r.strip()][:frames]
    return bvh.loads(f"{head}MOTION\nFrames: {len(rows)}\n{lines[1]}\n" + "\n".join(rows))


@pytest.mark.skipif(not every_shared_bvh(), reason=f"shared data not available at {DATA_DIR}")
def test_every_shared_bvh_maps_by_name_and_comes_back_within_one_percent():
    worst = {}
    for rel in every_shared_bvh():
        m = head_of(DATA_DIR / rel)
        rig = RT.make_rig(m.skeleton, m)
        assert rig.method == "names" and rig.confidence >= 0.9, (rel, rig.confidence)
        idx = [v for k, v in rig.mapping.items() if k != "joint_Root"]
        ref = RT.K.global_positions(m)[:, idx]
        canon = RT.to_canonical(m, rig, fps=None)
        back = RT.from_canonical(canon, rig, like=m)
        assert np.abs(RT.K.global_positions(back)[:, idx] - ref).max() < 1e-6 * rig.height
        alone = RT.from_canonical(canon, rig)
        err = np.linalg.norm(RT.K.global_positions(alone)[:, idx] - ref, axis=-1) / rig.height
        worst[rel] = float(np.percentile(err, 95))
    assert max(worst.values()) < 0.01, sorted(worst.items(), key=lambda kv: -kv[1])[:5]

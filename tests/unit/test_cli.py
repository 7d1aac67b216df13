"""The motion command line, run as a real subprocess."""

from __future__ import annotations

import json
import subprocess
import sys

from motion import bvh
from motion import canonical as C
from tests import rigs
from tests.conftest import REPO, data_path


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "motion", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )


def test_info_reports_mapping_and_unmapped_joints():
    r = run("info", str(rigs.FIXTURE))
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["frames"] == 60 and abs(info["fps"] - 30) < 1e-3 and info["mappable"]
    assert info["mapping"]["UpperLeg_L"] == "LeftUpLeg" and info["mapping"]["Chest"] == "Spine1"
    assert "LThumb" in info["unmapped"] and info["missing"] == []
    assert info["up_axis"] == "Y" and info["reference_pose"] == "rest"
    assert info["method"] == "names" and info["confidence"] == 1.0
    assert info["convention"].startswith("MotionBuilder")


def test_info_says_a_rig_without_names_was_mapped_by_structure(tmp_path):
    path = tmp_path / "numbered.bvh"
    numbered = rigs.renamed_numbers(rigs.load_fixture())
    bvh.save(numbered, path)
    r = run("info", str(path))
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["mappable"] and info["method"] == "structure" and 0 < info["confidence"] <= 1
    by_name = dict(zip(numbered.skeleton.names, rigs.load_fixture().skeleton.names, strict=True))
    assert by_name[info["mapping"]["UpperLeg_L"]] == "LeftUpLeg"
    assert by_name[info["mapping"]["Hand_R"]] == "RightHand"


def test_info_on_an_ambiguous_rig_names_the_chains_and_the_way_out(tmp_path):
    from tests.unit.test_rig_mapping import featureless

    path = tmp_path / "still.bvh"
    bvh.save(featureless(rigs.load_fixture()), path)
    r = run("info", str(path))
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert not info["mappable"] and "left from right" in info["error"]
    assert {c["limbs"] for c in info["ambiguous"]} == {"legs", "arms"}
    assert "UpperLeg_L" in info["mapping_example"]


def test_canonical_and_retarget_write_valid_bvh(tmp_path):
    out = tmp_path / "canon.bvh"
    r = run("canonical", str(rigs.FIXTURE), "-o", str(out))
    assert r.returncode == 0, r.stderr
    canon = bvh.load(out)
    assert canon.skeleton.names == C.JOINTS and round(canon.fps) == 30
    onto = tmp_path / "mixamo.bvh"
    bvh.save(rigs.renamed(rigs.load_fixture(), rigs.CMU_TO_MIXAMO), onto)
    res = tmp_path / "res.bvh"
    r = run("retarget", str(out), "--onto", str(onto), "-o", str(res))
    assert r.returncode == 0, r.stderr
    m = bvh.load(res)
    assert m.skeleton.names[0] == "mixamorig:Hips" and m.num_frames == canon.num_frames


def test_retarget_real_dance_onto_bandai(tmp_path):
    src = data_path("cmu-dance-43", "05_11_pirouette.bvh")
    onto = data_path("bandai", "dataset-1", "dataset-1_walk_normal_001.bvh")
    res = tmp_path / "res.bvh"
    r = run("retarget", str(src), "--onto", str(onto), "-o", str(res))
    assert r.returncode == 0, r.stderr
    assert bvh.load(res).skeleton.num_joints == 22


def test_errors_are_one_line_with_status_2(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    r = run("info", str(bad))
    assert r.returncode == 2 and "line 4" in r.stderr and "OFFSET" in r.stderr
    r = run("info", str(tmp_path / "missing.bvh"))
    assert r.returncode == 2 and "missing.bvh" in r.stderr
    r = run("canonical", str(rigs.FIXTURE), "-o", str(tmp_path / "x.bvh"), "--mapping", "{bad")
    assert r.returncode == 2 and "--mapping is not JSON" in r.stderr

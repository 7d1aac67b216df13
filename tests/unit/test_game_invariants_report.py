"""``training.game_invariants``: its measures on real clips, and its report recorded in the
manifest (the full run, every style of both families, is ``make game-invariants``)."""

from __future__ import annotations

import json
import shutil

import pytest

from model_export import evaluations as EV
from motion import bvh, retarget
from motion.reference import leading_reference_frames, rest_on_canonical
from motion.root_motion import in_place
from service.config import Settings
from service.manifest import load_manifest
from tests.conftest import data_path
from training import game_invariants as GI


@pytest.fixture(scope="module")
def walk():
    return bvh.load(data_path("bandai", "dataset-1", "dataset-1_walk_normal_002.bvh"))


def test_a_bind_pose_put_in_front_is_a_reference_frame(walk):
    for motion, count in ((walk, 0), (GI.with_bind_pose_first(walk), 1)):
        rig = retarget.make_rig(motion.skeleton, motion)
        full = retarget.to_canonical(motion, rig, fps=None)
        assert leading_reference_frames(full, rest_on_canonical(rig, motion.fps)) == count


def test_an_authored_cycle_jumps_nowhere_and_in_place_holds_still(walk):
    assert GI.loop_jump_in_steps(walk) < 1e-6  # its last frame repeats its first
    assert GI.hips_travel(walk) > 0.5  # the travel is on joint_Root
    hips = retarget.make_rig(walk.skeleton, walk).mapping["Hips"]
    assert GI.hips_travel(in_place(walk, hips)) < 1e-6


def test_the_report_goes_into_both_restyling_families_entries(tmp_path):
    models = tmp_path / "models"
    shutil.copytree(Settings().models_dir[0], models)
    entries = {m.family: m for m in load_manifest(models).models}
    families = ("translator", "fast")

    def per_family(value: float) -> dict:
        return {f: {"worst": value, "style": "happy"} for f in families}

    report = {
        "models": {f: {"name": entries[f].name, "version": entries[f].version} for f in families},
        "loops": {"dash": {"frames": 20, "taken_as_loop": True, "jump_steps": per_family(1.3)}},
        "reference_frames": {
            "05_20": {"found": True, "first_frame_moved_share_of_height": per_family(0.0)}
        },
        "in_place": {
            "run": {"sent_travel_share_of_height": 1.3, "travel_share_of_height": per_family(0.001)}
        },  # fmt: skip
        "reference_frames_found_in_bandai": {"takes": 454, "found": []},
        "measured": "2026-11-28",
    }
    path = tmp_path / "game-invariants.json"
    path.write_text(json.dumps(report))
    assert EV.main([str(path), "--models-dir", str(models)]) == 0
    for family in families:
        entry = next(m for m in load_manifest(models).models if m.family == family)
        recorded = entry.metrics["evaluation"]["game_invariants_held_back"]
        assert recorded["loop_jump_median_steps"] == {"dash": 1.3}
        assert recorded["in_place_travel_share_of_height"] == {"run": 0.001}
        assert recorded["every_reference_frame_found"] is True
        assert recorded["bandai_takes_found_with_reference_frames"] == 0

"""The foreign-content yardstick: its measures on motions whose answer is known, its split
into halves, its rig variants, the merged style names, and one end-to-end run."""

from __future__ import annotations

import numpy as np
import pytest

from model_export import evaluations as EV
from motion import bvh, retarget
from motion import canonical as C
from motion import features as Fe
from motion import kinematics as K
from motion import rotations as rot
from motion.skeleton import Motion
from motion.styles import STYLE_ALIASES, canonical_style
from tests.rigs import FIXTURE
from training import eval_foreign as EF
from training import foreign_content as FC
from training import foreign_judge as FJ
from training import foreign_measures as FM
from training import foreign_report as FR
from training import judges

# the styles Bandai's dataset 2 performs, the only ones with validation takes
DATASET_2_STYLES = {"active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"}

BANDAI_STYLES = (
    "normal", "happy", "sad", "angry", "proud", "not-confident", "masculinity", "feminine",
    "childish", "old", "tired", "active", "musical", "giant", "chimpira",  # dataset-1
    "active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful",  # dataset-2
)  # fmt: skip


def swinging(frames: int = 120, hz: float = 1.0, phase: float = 0.0, sideways: bool = False):
    """A canonical body standing in place, arms and legs swinging at ``hz`` (left and right in
    opposition): forward and back, or with ``sideways`` out to the sides and up."""
    t = np.arange(frames) / C.FPS
    angle = 0.6 * np.sin(2 * np.pi * hz * t + phase)
    arms = np.array([0.0, 0.0, 1.0] if sideways else [0.0, 1.0, 0.0])  # the rest arm lies along x
    legs = np.array([0.0, 0.0, 1.0] if sideways else [1.0, 0.0, 0.0])  # the rest leg along -y
    lrot = rot.identity((frames, len(C.JOINTS)))
    for name, sign, axis in (("UpperArm_L", 1, arms), ("UpperArm_R", -1, arms),
                             ("UpperLeg_L", -1, legs), ("UpperLeg_R", 1, legs)):  # fmt: skip
        lrot[:, C.INDEX[name]] = rot.from_rotvec(sign * angle[:, None] * axis)
    lpos = np.repeat(C.OFFSETS[None], frames, axis=0)
    lpos[:, 0] = 0.0
    lpos[:, 1] = [0.0, 90.0, 0.0]
    return Motion(C.SKELETON, C.FPS, lrot, lpos)


def test_merged_names_are_sixteen_and_each_alias_scores_as_its_twin():
    assert canonical_style("old") == "elderly" and canonical_style("tired") == "exhausted"
    assert canonical_style("masculinity") == "masculine" and canonical_style("happy") == "happy"
    assert len(set(BANDAI_STYLES)) == 19 and len({canonical_style(s) for s in BANDAI_STYLES}) == 16
    assert set(STYLE_ALIASES.values()) <= set(BANDAI_STYLES)


def test_content_kept_is_one_for_the_motion_itself_and_for_a_time_warped_copy():
    motion = swinging()
    assert FM.content_kept(motion, motion) == pytest.approx(1.0, abs=1e-9)
    for factor in (0.6, 1.5):  # the output of a time warp, brought back onto the content's frames
        warped = Fe.time_warp(motion, factor)
        assert warped.num_frames != motion.num_frames
        assert FM.content_kept(warped, motion) > 0.99


def test_content_kept_is_low_for_an_unrelated_motion():
    sideways = swinging(hz=1.7, phase=1.0, sideways=True)
    assert abs(FM.content_kept(sideways, swinging())) < 0.3


def test_effector_paths_are_in_the_bodys_own_frame():
    """Turning and moving the whole body leaves hands and feet relative to the hips as they were."""
    motion = swinging()
    turn = rot.about_y(np.full(motion.num_frames, 2.0))
    lrot, lpos = motion.lrot.copy(), motion.lpos.copy()
    lrot[:, 1] = rot.mul(turn, lrot[:, 1])
    lpos[:, 1] += [30.0, 0.0, -200.0]
    moved = motion.replace(lrot=lrot, lpos=lpos)
    np.testing.assert_allclose(FM.effector_paths(moved), FM.effector_paths(motion), atol=1e-6)


def test_spread_is_zero_for_identical_outputs_and_averages_two_names_of_one_style():
    same = np.tile(np.arange(6.0), (4, 1))
    assert FM.style_spread(same, ["angry", "sad", "proud", "happy"]) == 0.0
    rows = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 5.0]])  # elderly's two names average to (1, 0)
    styles = [canonical_style(n) for n in ("old", "elderly", "sad")]
    assert FM.style_spread(rows, styles) == pytest.approx(5.0)
    assert FM.mean_pairwise_distance(np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 0.0]])) == (
        pytest.approx(10.0 / 3.0)
    )


def test_descriptors_tell_motions_apart_and_ignore_where_the_body_stands():
    a, b = swinging(), swinging(hz=2.5, sideways=True)
    lpos = a.lpos.copy()
    lpos[:, 1] += [100.0, 0.0, 50.0]
    np.testing.assert_allclose(FM.descriptor(a), FM.descriptor(a.replace(lpos=lpos)), atol=1e-6)
    assert np.linalg.norm(FM.descriptor(a) - FM.descriptor(b)) > 0.1


def test_recognition_counts_top1_top3_recall_and_the_most_predicted_style():
    classes = ["a", "b", "c", "d"]
    logp = np.log(
        np.array([
            [0.7, 0.1, 0.1, 0.1],  # asked a, said a
            [0.1, 0.2, 0.6, 0.1],  # asked b, said c (b second)
            [0.1, 0.2, 0.6, 0.1],  # asked c, said c
            [0.6, 0.1, 0.2, 0.1],  # asked d, said a, d last
            [0.1, 0.1, 0.7, 0.1],  # asked c, said c
        ])
    )  # fmt: skip
    got = FJ.recognition(["a", "b", "c", "d", "c"], logp, classes)
    assert got["top1"] == pytest.approx(3 / 5) and got["top3"] == pytest.approx(4 / 5)
    assert got["recall"] == {"a": 1.0, "b": 0.0, "c": 1.0, "d": 0.0}
    assert got["top1_mean_per_style"] == pytest.approx(0.5)
    assert got["most_predicted"] == "c" and got["most_predicted_share"] == pytest.approx(3 / 5)
    assert got["confusion"]["b"] == {"c": 1} and got["under_30"] == ["b", "d"]


def test_within_actor_recall_only_chooses_among_one_actors_styles():
    classes = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]

    def row(style, probs, dataset="dataset-2"):
        return {"style": style, "dataset": dataset, "logp": np.log(np.asarray(probs))}

    held = [
        row("elderly", [0.1, 0.25, 0.2, 0.01, 0.01, 0.42, 0.01]),  # normal, elderly in-group
        row("exhausted", [0.5, 0.1, 0.2, 0.05, 0.05, 0.05, 0.05]),  # active, an actor-mate
        row("elderly", [0.01, 0.01, 0.9, 0.05, 0.01, 0.01, 0.01], dataset="dataset-1"),
    ]  # fmt: skip
    group = FJ.within_actor(held, classes)["active, elderly, exhausted"]
    assert group["n"] == 2 and group["recall_within_group"] == 0.5
    assert group["top1"] == 0.0 and group["chance"] == pytest.approx(1 / 3, abs=1e-4)


def test_every_bandai_action_falls_in_one_of_five_groups():
    index = {
        "walks": (
            "walk",
            "walk-back",
            "walk-left",
            "walk-right",
            "walk-turn-left",
            "walk-turn-right",
        ),
        "runs": ("run", "dash"),
        "waves": ("bye", "byebye", "wave-both-hands", "wave-left-hand", "wave-right-hand"),
        "raises": ("raise-up-both-hands", "raise-up-left-hand", "raise-up-right-hand"),
        "other": ("bow", "guide", "respond", "call", "punch", "kick", "slash", "dance-short"),
    }
    for group, contents in index.items():
        assert {FJ.action_group(c) for c in contents} == {group}


def _takes():
    return {
        "cmu-31": [f"cmu-31/{i:02d}_01" for i in range(9)],
        "xia": [f"xia/clip_{i}" for i in range(9)],
        "cmu-dance-43": [f"cmu-dance-43/dance_{i}" for i in range(5)],
        "cmu-dance-3dsmax": ["cmu-dance-3dsmax/94_01"],
    }


def test_split_is_deterministic_by_take_and_balanced_across_folders():
    takes = _takes()
    half_of = FC.split_halves(takes)
    shuffled = {f: list(reversed(v)) for f, v in reversed(list(takes.items()))}
    assert FC.split_halves(shuffled) == half_of  # no dependence on listing order
    every = [t for v in takes.values() for t in v]
    assert sorted(half_of) == sorted(every) and set(half_of.values()) == {"dev", "test"}
    for names in takes.values():
        halves = [half_of[t] for t in names]
        assert abs(halves.count("dev") - halves.count("test")) <= 1
    assert abs(list(half_of.values()).count("dev") - len(every) / 2) <= 0.5
    takes["xia"].append("xia/clip_new")  # another take changes only its own folder and later
    assert {t: h for t, h in FC.split_halves(takes).items() if t.startswith("cmu-31")} == {
        t: h for t, h in half_of.items() if t.startswith("cmu-31")
    }


def test_segments_are_at_most_eight_seconds_and_at_most_four():
    for frames, count, longest in ((30, 1, 30), (274, 2, 137), (900, 4, 225), (2575, 4, 240)):
        parts = judges.segments(swinging(frames=frames))
        assert len(parts) == count and max(p.num_frames for p in parts) == longest
        assert parts[0].lrot[0].tolist() == swinging(frames=frames).lrot[0].tolist()


def test_rig_variants_read_through_the_service_match_the_original():
    original = bvh.load(FIXTURE)
    canon = K.global_positions(retarget.to_canonical(original))
    for name, variant in FC.rig_variants(original).items():
        names = variant.skeleton.names
        assert any(n.startswith("mixamorig:") for n in names) == (name == "mixamo")
        back = K.global_positions(FC.through_service(variant))
        assert back.shape == canon.shape
        np.testing.assert_allclose(back, canon, atol=0.01, err_msg=name)


def test_the_split_covers_every_source_folder():
    from tests.conftest import data_path

    root = data_path("cmu-31").parent
    takes = FC.foreign_takes(root)
    assert set(takes) == set(FC.FOLDERS) and all(takes.values())
    every = [t.split("/")[1] for v in takes.values() for t in v]
    assert len(every) == len(set(every)) == 24  # CMU 05_20, in two folders, once
    half_of = FC.split_halves(takes)
    for folder, names in takes.items():  # cmu-dance-3dsmax has one take, in one half
        halves = {half_of[t] for t in names}
        assert halves == {"dev", "test"} or (len(names) == 1 and len(halves) == 1), folder


def test_log_probabilities_rank_the_classes_the_prediction_takes():
    from training.judges import ConvClipClassifier

    rng = np.random.default_rng(0)
    feats = [rng.normal(size=(60, 5)).astype(np.float32) + k for k in (0, 0, 3, 3)]
    clf = ConvClipClassifier(feats, ["low", "low", "high", "high"], seeds=(0,), steps=5)
    logp = clf.log_probabilities(feats[2])
    assert logp.shape == (2,) and np.all(logp <= 0.0)
    assert clf.classes[int(np.argmax(logp))] == clf.predict(feats[2])


def test_a_cached_judge_is_kept_for_the_same_code_and_motion_and_only_for_them():
    from dataclasses import replace

    from training.data import clip_from_motion

    clips = [
        clip_from_motion(swinging(hz=hz), name=n, dataset="d", take=n, style=s, content="walk")
        for n, hz, s in (("a", 1.0, "old"), ("b", 1.5, "happy"))
    ]
    key = FJ.judge_key(clips)
    assert FJ.judge_key(list(reversed(clips))) == key
    moved = clips[0].root.copy()
    moved[5, 1] += 0.01  # a retargeting change the clip cache would not notice
    assert FJ.judge_key([replace(clips[0], root=moved), clips[1]]) != key
    assert FJ.judge_key([replace(clips[0], style="sad"), clips[1]]) != key
    read = {p.name for p in FJ.motion_sources("features", "canonical", "styles")}
    assert {"features.py", "kinematics.py", "rotations.py", "styles.py"} <= read
    assert not {"audio_features.py", "retarget.py", "gltf.py"} & read  # their edits keep the judge


def test_evaluation_runs_end_to_end_on_the_shipped_models(tmp_path, monkeypatch):
    """:func:`evaluate` with both shipped families (the translator also by style clips and
    videos, all takes and unseen ones) on one item of the test half and a judge trained a
    few steps (a full run's took 51 minutes on two busy cores), its tables and its
    records."""
    import shutil

    from service.config import Settings
    from service.manifest import load_manifest
    from tests.conftest import data_path
    from training.judges import ConvClipClassifier

    data_path("bandai")
    data_path("cmu-31")
    monkeypatch.setattr(ConvClipClassifier.__init__, "__defaults__", ((0,), 3))
    report = EF.evaluate(("test",), limit=1, log=lambda *_: None)["test"]
    assert report["half"] == "test" and report["items"] == 1 and len(report["styles"]) == 16
    shipped = report["families"]["translator"]["names_sent"]
    assert len(shipped) == 16
    for family in EF.FAMILIES:
        figures = report["families"][family]
        names = figures["names_sent"]
        assert set(names) == (DATASET_2_STYLES if family.endswith("-unseen") else set(shipped))
        assert figures["n"] == len(names) and set(figures["top1_by_name"]) == set(names)
        assert 0.0 <= figures["top1"] <= figures["top3"] <= 1.0
        assert figures["spread_ratio"] > 0.0 and -1.0 <= figures["content_kept"] <= 1.0
        assert sum(b["n"] for b in figures["by_source"].values()) == len(names)
        limbs = figures["anatomy"]
        assert 0.0 <= limbs["knees_backwards"] <= limbs["knees_backwards_worst_clip"] <= 1.0
        assert 0.0 <= limbs["elbows_backwards"] <= limbs["elbows_backwards_worst_clip"] <= 1.0
        assert 0.0 < limbs["peak_speed_p99_bh_s"] <= limbs["peak_speed_bh_s"]
        jitter = figures["held_out_jitter"]
        if family in EF.ADAPTERS:  # the families with networks of their own
            assert jitter["takes"] == 29 and jitter["real_m_s3"] > 0.0
            assert 0.3 < jitter["ratio"] < 3.0  # neither frozen nor shaking
        else:
            assert jitter is None
    real = report["real_bandai"]["anatomy"]  # 3 frames of 76,197 (a dance); a sprint's 6.8
    assert real["knees_backwards"] < 1e-4 and 6.0 < real["peak_speed_bh_s"] < 8.0
    assert real["elbows_backwards"] < 1e-4  # none of 76,197 frames
    reference = report["real_bandai"]["leave_action_out"]
    assert reference["n"] == 454
    clips = [g["n"] for g in reference["within_actor_groups"].values()]
    assert clips == [120, 80, 80]  # dataset-2's takes only: 40 per style
    assert "test half" in FR.markdown(report)
    models = tmp_path / "models"
    shutil.copytree(Settings().models_dir[0], models)
    EV.record_foreign(report, models)
    for family, figures in report["families"].items():
        entry = next(m for m in load_manifest(models).models if m.name == figures["model_name"])
        recorded = entry.metrics["evaluation"][EF.EVALUATION_KEY.get(family, "foreign_test_half")]
        assert recorded["items"] == 1 and recorded["top1"] == figures["top1"]
        assert recorded["anatomy"] == figures["anatomy"]
        assert recorded["real_anatomy"] == report["real_bandai"]["anatomy"]
        assert recorded["content_anatomy"] == report["unchanged"]["anatomy"]
    with pytest.raises(ValueError, match="test half"):
        EV.record_foreign({**report, "half": "dev"}, models)


def test_unseen_style_clips_come_only_from_takes_the_encoders_never_trained_on():
    from tests.conftest import data_path
    from training.bandai_library import held_out_take
    from training.data import load_bandai

    data_path("bandai")
    clips = load_bandai()
    unseen, every = EF.ByStyleClip(clips, unseen=True), EF.ByStyleClip(clips)
    assert set(unseen.takes) == DATASET_2_STYLES and len(every.takes) == 16
    assert all(held_out_take(c.name) for takes in unseen.takes.values() for c in takes)
    assert sum(map(len, unseen.takes.values())) < sum(map(len, every.takes.values())) / 8
    names = ["angry", "elderly", "old", "tired", "youthful"]
    assert unseen.sendable(names) == ["elderly", "old", "tired", "youthful"]
    assert every.sendable(names) == names


def test_a_pinned_judge_reads_back_the_same_and_refuses_changed_features(tmp_path):
    from dataclasses import replace

    from training.data import clip_from_motion
    from training.judges import ConvClipClassifier, frame_features

    clips = [
        clip_from_motion(swinging(hz=hz), name=n, dataset="d", take=n, style=s, content="walk")
        for n, hz, s in (("a", 1.0, "old"), ("b", 1.5, "happy"))
    ]
    classifier = ConvClipClassifier(
        [frame_features(c.motion) for c in clips], ["old", "happy"], seeds=(0,), steps=3
    )
    held_out = [{"take": "a", "style": "old", "group": "walks", "logp": np.log([0.3, 0.7])}]
    judge = FJ.StyleJudge(classifier, held_out)
    path = tmp_path / "judge.pt"
    FJ.pin_judge(judge, clips, path)
    back = FJ.pinned_judge(path, clips)
    assert back.classes == judge.classes and back.held_out[0]["take"] == "a"
    np.testing.assert_array_equal(back.held_out[0]["logp"], held_out[0]["logp"])
    for c in clips:
        np.testing.assert_array_equal(
            back.log_probabilities(c.motion), judge.log_probabilities(c.motion)
        )
    faster = clip_from_motion(swinging(hz=2.5), name="b", dataset="d", take="b", style="happy")
    with pytest.raises(ValueError, match="judges take b differently"):
        FJ.pinned_judge(path, [clips[0], replace(faster, content="walk")])
    assert FJ.judge_for(clips, None, path).classes == judge.classes  # the file, not training


def test_intervals_resample_takes_not_outputs():
    """Two takes of three outputs each: one take all right, the other all wrong. Drawn by
    take, some resamples hold only the one or only the other, so top-1 runs from 0 to 1;
    the same six outputs in six takes of their own could not stray so far."""
    requested = ["a", "b", "c", "a", "b", "c"]
    predicted = ["a", "b", "c", "b", "c", "a"]
    by_take = EF.take_intervals(["t1"] * 3 + ["t2"] * 3, requested, predicted, resamples=400)
    assert by_take["top1"] == [0.0, 1.0]
    assert by_take["lowest_recall"][0] == 0.0
    apart = EF.take_intervals([f"t{k}" for k in range(6)], requested, predicted, resamples=400)
    assert 0.0 < apart["top1"][0] <= 0.5 <= apart["top1"][1] < 1.0
    everything_right = EF.take_intervals(["t1", "t1", "t2"], ["a", "b", "a"], ["a", "b", "a"])
    assert everything_right["top1"] == [1.0, 1.0]
    assert everything_right["lowest_recall"] == [1.0, 1.0]
    assert 0.5 <= everything_right["most_predicted_share"][0] <= 1.0


@pytest.mark.parametrize("source", ["clip", "video"])
def test_short_style_clips_codes_each_take_cut_then_whole(tmp_path, monkeypatch, source):
    """``training.short_style_clips`` on two items of the dev half: the encoder codes a
    1-frame cut of each style take (as a clip, or as a video's keypoints), then the whole
    takes for ``0``."""
    import json

    from tests.conftest import data_path
    from training import short_style_clips as SSC

    data_path("bandai")
    data_path("cmu-31")
    coded: list[int] = []
    style_code_job = EF.StyleCodeJob

    def job(style):  # the frames each style code is computed from
        coded.append(len(style.positions) if source == "video" else style.num_frames)
        return style_code_job(style)

    monkeypatch.setattr(EF, "StyleCodeJob", job)
    out = tmp_path / "short.json"
    SSC.main([str(out), "--limit", "2", "--source", source, "--frames", "1", "0"])
    report = json.loads(out.read_text())
    assert report["source"] == source
    assert [r["frames"] for r in report["rows"]] == [1, 0]
    assert all(0.0 <= r["top1"] <= 1.0 and r["outputs"] > 0 for r in report["rows"])
    assert report["rows"][0]["outputs"] == report["rows"][1]["outputs"]
    cuts = coded[: len(coded) // 2]
    assert cuts and set(cuts) == {1} and min(coded[len(coded) // 2 :]) > 30

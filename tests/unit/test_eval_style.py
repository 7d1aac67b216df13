"""The evaluation's window features, and their mirror images."""

from __future__ import annotations

import numpy as np
import pytest

from motion import bvh, retarget
from motion import canonical as C
from motion.skeleton import Motion
from tests.rigs import FIXTURE
from training import eval_style as ES


def test_mirror_swaps_sides_and_keeps_what_has_no_side():
    motion = retarget.to_canonical(bvh.load(FIXTURE))
    plain, mirrored = ES.window_features(motion), ES.window_features(motion, mirror=True)
    assert plain.shape == mirrored.shape and not np.allclose(plain, mirrored)
    joints = len(C.JOINTS)
    speeds = slice(3 * joints, 4 * joints)  # per-frame layout: positions, speeds, root...
    left, right = C.INDEX["Hand_L"], C.INDEX["Hand_R"]
    np.testing.assert_allclose(plain[:, speeds][:, left], mirrored[:, speeds][:, right])
    tail = slice(4 * joints, 4 * joints + 4)  # root speeds, turning, hips height
    np.testing.assert_allclose(np.abs(plain[:, tail]), np.abs(mirrored[:, tail]), atol=1e-6)
    twice = [ES._MIRROR[j] for j in ES._MIRROR]
    assert twice == list(range(joints))


def test_frame_features_mirror_swaps_sides():
    motion = retarget.to_canonical(bvh.load(FIXTURE))
    plain, mirrored = ES.frame_features(motion), ES.frame_features(motion, mirror=True)
    assert plain.shape == mirrored.shape == (motion.num_frames, 130)
    body = [C.JOINTS[j] for j in range(1, len(C.JOINTS))]
    left, right = body.index("Hand_L"), body.index("Hand_R")
    pos = lambda f, j: f[:, 3 * j : 3 * j + 3]  # noqa: E731
    np.testing.assert_allclose(pos(mirrored, right), pos(plain, left) * [-1, 1, 1], atol=1e-6)
    np.testing.assert_allclose(mirrored[:, -4], plain[:, -4])  # hips height has no side
    np.testing.assert_allclose(mirrored[:, -1], -plain[:, -1])  # turning left becomes right


def test_conv_classifier_learns_what_tells_clips_apart(monkeypatch):
    rng = np.random.default_rng(0)
    features, labels = [], []
    for k, label in enumerate(("calm", "lively")):
        for _ in range(4):  # "lively" clips oscillate fast in one channel, "calm" ones slowly
            t = np.arange(rng.integers(30, 90))
            x = 0.3 * rng.normal(size=(len(t), 6))
            x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2))
            features.append(x.astype(np.float32))
            labels.append(label)
    import torch

    train, seen = ES.ConvClipClassifier._train_on_this_thread, []
    monkeypatch.setattr(
        ES.ConvClipClassifier, "_train_on_this_thread",
        lambda self, *a: seen.append(torch.get_num_threads()) or train(self, *a),
    )  # fmt: skip
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        clf = ES.ConvClipClassifier(features, labels, seeds=(0,), steps=150)
        assert seen == [1] and torch.get_num_threads() == 2  # one thread, the caller's kept
    finally:
        torch.set_num_threads(threads)
    t = np.arange(70)
    for k, label in enumerate(("calm", "lively")):
        x = 0.3 * rng.normal(size=(len(t), 6))
        x[:, 0] += np.sin(t * (0.1 if k == 0 else 1.2) + 1.0)
        assert clf.predict(x.astype(np.float32)) == label


def _left_arm_raised(angle: float) -> Motion:
    """The canonical rest pose (arms out sideways) with the left arm turned ``angle`` up."""
    lrot = np.zeros((30, len(C.JOINTS), 4))
    lrot[..., 3] = 1.0
    lrot[:, C.INDEX["UpperArm_L"], 2] = np.sin(angle / 2)
    lrot[:, C.INDEX["UpperArm_L"], 3] = np.cos(angle / 2)
    lpos = np.repeat(C.OFFSETS[None], 30, axis=0)
    return Motion(C.SKELETON, 30.0, lrot, lpos)


def test_hand_reach_is_how_far_the_higher_hand_gets_above_the_head():
    arm = float(np.linalg.norm(C.OFFSETS[C.INDEX["Hand_L"]]))  # forearm
    arm += float(np.linalg.norm(C.OFFSETS[C.INDEX["LowerArm_L"]]))  # upper arm
    level, up = ES.hand_reach(_left_arm_raised(0.0)), ES.hand_reach(_left_arm_raised(np.pi / 2))
    assert level < 0.0  # arms out sideways: hands at shoulder height, below the head
    np.testing.assert_allclose(up - level, arm, rtol=1e-6)  # the whole arm now points up
    assert ES.raises_a_hand("wave-left-hand") and ES.raises_a_hand("raise-up-both-hands")
    assert not ES.raises_a_hand("walk") and not ES.raises_a_hand("bow")


def test_tally_counts_both_content_classifiers_and_the_table_shows_them():
    t = ES.Tally()
    source = ES.Verdict("sad", "sad", "walk", "walk", "walk", "walk", 2.0, 10.0, (0.6, 0.0), 40.0)
    t.add(
        ES.Verdict("angry", "sad", "walk", "run", "walk", "run", 2.0, -30.0, (0.0, 0.0), 50.0),
        "angry", "walk", source, "sad",
    )  # fmt: skip
    t.add(
        ES.Verdict("sad", "sad", "run", "run", "walk", "walk", 4.0, -40.0, (0.0, 0.0), 40.0),
        "angry", "run", source, "sad",
    )  # fmt: skip
    t.add(
        ES.Verdict("sad", "sad", "walk", "run", "wave-left-hand", "wave-left-hand", 3.0, 12.5, (0.9, 0.7), 0.0),
        "angry", "wave-left-hand", source, "sad",
    )  # fmt: skip
    row = t.summary()
    assert row["style_accuracy"] == 0.3333 and row["style_accuracy_linear"] == 0.0
    assert row["style_as_source"] == 0.6667  # two of three read as sad, the content's style
    own, unlabelled = ES.Tally(), ES.Tally()
    own.add(source, "sad", "walk", source, "sad")  # sent to its own style: not counted
    unlabelled.add(source, "angry", "walk", source)
    assert own.summary()["style_as_source"] is None is unlabelled.summary()["style_as_source"]
    assert row["content_accuracy"] == 0.6667 and row["content_accuracy_conv"] == 0.3333
    assert row["content_accuracy_all_takes"] == 0.6667
    assert row["content_accuracy_all_takes_merged"] == 0.6667  # run is not a walk
    assert row["content_accuracy_unseen_takes"] == 0.3333
    assert row["content_missed_all_takes"] == {"run -> walk": 1}
    assert row["hand_actions"] == 1 and row["hand_reach_cm"] == 12.5  # hand actions only
    assert row["hand_use_error"] == 0.5  # (|0.9 - 0.6| + |0.7 - 0|) / 2, hand actions only
    assert row["turning_error_deg"] == pytest.approx((10 + 0 + 40) / 3, abs=0.05)
    report = {
        "family": "translator", "model": "m 1", "held_out_takes": 2, "takes_of": "translator",
        "takes_unseen_by_family": 2, "styles": 2, "chance_style": 0.5, "chance_content": 0.5,
        "rows": {"translator": row, "translator (pairs): hand actions": ES.Tally().summary()},
        "per_style": {}, "per_style_real_target": {},
    }  # fmt: skip
    table = ES.markdown(report)
    assert "hand actions" not in table  # a split no clip fell into is left out, not a crash
    assert "content accuracy (conv)" in table and "content accuracy (all takes)" in table
    assert "content accuracy (unseen takes)" in table
    assert (
        "| translator | 3 | 33.3% | 0.0% | 66.7% | 66.7% | 33.3% | 66.7% | 66.7% | 33.3% | 3.0 "
        "| +12.5 (1) "
        "| 50.0% | 16.7 |" in table
    )
    assert "- translator: run -> walk: 1" in table


def test_gap_intervals_resample_takes_and_need_the_same_clips():
    source = ES.Verdict("sad", "sad", "walk", "walk", "walk", "walk", 2.0, 0.0, (0.0, 0.0), 0.0)
    right = ES.Verdict("angry", "angry", "walk", "walk", "walk", "walk", 2.0, 0.0, (0.0, 0.0), 0.0)
    wrong = ES.Verdict("sad", "sad", "run", "run", "run", "run", 2.0, 0.0, (0.0, 0.0), 0.0)
    transfers, real = ES.Tally(), ES.Tally()
    # take a: the transfer right 2 of 4 times, the real clip 4 of 4; take b: both 4 of 4
    for take, outs in (("a", [right, wrong, right, wrong]), ("b", [right] * 4)):
        for out in outs:
            transfers.add(out, "angry", "walk", source, "sad", take)
            real.add(right, "angry", "walk", source, "sad", take)
    g = ES.gap_interval(transfers, real, "style", draws=400)
    assert g["gap"] == -0.25 and g["takes"] == 2
    # resampling two takes gives means of -0.5 (a twice), -0.25 or 0 (b twice), nothing else
    assert g["low"] == -0.5 and g["high"] == 0.0
    same = ES.gap_interval(real, real, "content_all")
    assert same == {"gap": 0.0, "low": 0.0, "high": 0.0, "takes": 2}
    assert ES.gap_interval(ES.Tally(), ES.Tally(), "style") is None
    other = ES.Tally()
    other.add(right, "angry", "walk", source, "sad", "c")
    with pytest.raises(ValueError, match="same clips"):
        ES.gap_interval(transfers, other, "style")
    rows = {"translator": transfers, "translator (pairs with a real target)": transfers,
            "real target": real, "unchanged": real}  # fmt: skip
    found = ES.gaps(rows, "translator")
    assert found["style: translator (pairs) - real target"]["gap"] == -0.25
    assert found["content (all takes): translator - unchanged"]["gap"] == -0.25
    assert found["content (unseen takes): translator - unchanged"]["gap"] == -0.25
    report = {
        "family": "translator", "model": "m 1", "held_out_takes": 2, "takes_of": "translator",
        "takes_unseen_by_family": 2, "styles": 2, "chance_style": 0.5, "chance_content": 0.5,
        "rows": {"translator": transfers.summary()}, "per_style": {},
        "per_style_real_target": {}, "gaps": found,
    }  # fmt: skip
    assert "- style: translator (pairs) - real target: -25.0% (-50.0% to +0.0%, 2 takes)" in (
        ES.markdown(report)
    )


def test_merged_content_counts_a_turning_walk_read_as_a_walk_and_a_wave_by_either_name():
    t = ES.Tally()
    source = ES.Verdict("sad", "sad", "walk", "walk", "walk", "walk", 2.0, 0.0, (0.0, 0.0), 90.0)
    said = ["walk", "run", "walk-turn-right", "walk-turn-left"]
    for content_all in said:
        verdict = ES.Verdict(
            "sad", "sad", "walk", "walk", content_all, content_all, 2.0, 0.0, (0, 0), 90.0
        )
        t.add(verdict, "sad", "walk-turn-left", source)
    for content_all in ["bye", "byebye", "wave-left-hand"]:  # only bye is a right-hand wave
        verdict = ES.Verdict(
            "sad", "sad", "walk", "walk", content_all, content_all, 2.0, 0.0, (0, 0), 0.0
        )
        t.add(verdict, "sad", "wave-right-hand", source)
    row = t.summary()
    assert row["content_accuracy_all_takes"] == round(1 / 7, 4)  # walk-turn-left itself
    assert row["content_accuracy_all_takes_merged"] == round(4 / 7, 4)  # 3 walks and bye
    assert ES.merged("walk-back") == "walk-back"  # a different action, not merged


def test_merged_names_use_the_hands_alike():
    """The premise of the merged content figure, on the real clips: dataset 1's bye and
    byebye hold the same hands above the head, for as large a share of frames, as dataset
    2's wave-right-hand and wave-both-hands; a wave of the left hand does not match bye."""
    from tests.conftest import data_path
    from training.data import load_bandai

    data_path("bandai")  # skips without the Bandai data
    up: dict[str, list] = {}
    for clip in load_bandai():
        up.setdefault(clip.content, []).append(ES.hands_up(clip.motion))
    share = {content: np.mean(rows, axis=0) for content, rows in up.items()}
    for a, b in [("bye", "wave-right-hand"), ("byebye", "wave-both-hands")]:
        assert ES.merged(a) == ES.merged(b)
        assert np.abs(share[a] - share[b]).max() < 0.1, (a, share[a], b, share[b])
    assert share["bye"][0] < 0.05 < 0.4 < share["bye"][1]  # the right hand alone
    assert min(share["byebye"]) > 0.4  # both hands
    assert ES.merged("wave-left-hand") == "wave-left-hand"  # no dataset-1 twin
    assert np.abs(share["bye"] - share["wave-left-hand"]).max() > 0.4


def test_hands_up_and_turning_measure_what_a_clip_does():
    raised = _left_arm_raised(np.pi / 2)
    assert ES.hands_up(raised) == (1.0, 0.0) and ES.hands_up(_left_arm_raised(0.0)) == (0, 0)
    assert ES.turning(raised) == pytest.approx(0.0, abs=1e-6)
    turn = np.linspace(0.0, np.pi / 2, 30)  # the whole body turns 90 degrees to its left
    lrot = raised.lrot.copy()
    lrot[:, 0] = np.stack([0 * turn, np.sin(turn / 2), 0 * turn, np.cos(turn / 2)], axis=-1)
    turned = Motion(C.SKELETON, 30.0, lrot, raised.lpos)
    assert abs(ES.turning(turned)) == pytest.approx(90.0, abs=1.0)


def test_folded_classifier_judges_a_take_with_networks_that_never_saw_it():
    rng = np.random.default_rng(1)

    def wave(freq: float) -> np.ndarray:
        return np.sin(np.arange(60) * freq)[:, None] + 0.2 * rng.normal(size=(60, 3))

    shared = [wave(0.1).astype(np.float32), wave(1.2).astype(np.float32)]
    takes = [f"take-{i}" for i in range(12)]
    labels = ["calm" if i % 2 else "lively" for i in range(12)]
    labels[0] = "unique"  # a label only take-0 shows
    features = [wave(0.1 if lab == "calm" else 1.2).astype(np.float32) for lab in labels]
    clf = ES.FoldedClassifier(
        shared, ["calm", "lively"], features, labels, takes, folds=3, seeds=(0,), steps=5
    )
    own = clf.fold_of("take-0")
    assert all(0 <= clf.fold_of(t) < 3 for t in takes)
    assert "unique" not in clf.classifiers[own].classes
    assert all("unique" in clf.classifiers[k].classes for k in range(3) if k != own)
    assert clf.predict(features[1], own) in clf.classifiers[own].classes


def test_classifiers_are_kept_and_trained_again_only_for_other_takes(tmp_path, monkeypatch):
    from training.data import Clip

    monkeypatch.setattr(ES.ConvClipClassifier.__init__, "__defaults__", ((0,), 5))  # quick
    trained = []
    train = ES.train_classifiers
    monkeypatch.setattr(ES, "train_classifiers", lambda *a: trained.append(a) or train(*a))
    canon = retarget.to_canonical(bvh.load(FIXTURE))

    def clip(take: str, style: str, content: str) -> Clip:
        return Clip(take, "test", take, canon.lrot, canon.lpos[:, 1], style, content)

    held = [clip(f"h{i}", "ab"[i % 2], ("walk", "run")[i // 2]) for i in range(4)]
    training = [clip(f"t{i}", "ab"[i % 2], ("walk", "run")[i // 2]) for i in range(4)]
    first = ES.classifiers_for(held, training, True, tmp_path)
    again = ES.classifiers_for(held, training, True, tmp_path)
    assert len(trained) == 1 and len(list(tmp_path.glob("classifiers-*.pkl"))) == 1
    x = ES.frame_features(held[0].motion)
    for net, kept in zip(first.style_conv.nets, again.style_conv.nets, strict=True):
        assert torch_equal(net, kept)
    ES.classifiers_for(held[1:] + [clip("h0", "b", "walk")], training, True, tmp_path)  # label
    ES.classifiers_for(held, training[:3], True, tmp_path)  # takes
    ES.classifiers_for(held, training, False, tmp_path)  # no mirrors
    assert len(trained) == 4 and len(list(tmp_path.glob("classifiers-*.pkl"))) == 4
    assert again.content_all.predict(x, 0) in {"walk", "run"}
    assert again.content_unseen.predict(x, again.content_unseen.fold_of("h0")) in {"walk", "run"}
    ES.classifiers_for(held, training, True, None)  # no cache: trains
    assert len(trained) == 5


def test_the_classifier_cache_key_follows_the_code_that_judges(tmp_path, monkeypatch):
    key = ES.classifier_code_key()
    assert key == ES.classifier_code_key()  # stable
    feature_code = tmp_path / "features.py"
    feature_code.write_text("SCALE = 1.0\n")
    monkeypatch.setattr(ES, "_feature_sources", lambda: [feature_code])
    before = ES.classifier_code_key()
    assert before != key
    feature_code.write_text("SCALE = 2.0\n")  # the motion code the features come from
    assert ES.classifier_code_key() != before
    monkeypatch.setattr(ES, "HOP", ES.HOP + 1)  # a constant of the window statistics
    assert len({key, before, ES.classifier_code_key()}) == 3


def torch_equal(a, b) -> bool:
    return all(
        (p == q).all()
        for p, q in zip(a.state_dict().values(), b.state_dict().values(), strict=True)
    )


def test_evaluation_runs_end_to_end_on_the_shipped_translator(tmp_path, monkeypatch):
    """The whole of :func:`evaluate` with the shipped model on one held-out take and
    classifiers trained a few steps: a full run takes 13 minutes, and a crash in its last
    lines had been found only at the end of one."""
    from tests.conftest import data_path, recorded_evaluation

    data_path("bandai")  # skips without the Bandai data
    monkeypatch.setattr(ES.ConvClipClassifier.__init__, "__defaults__", ((0,), 5))  # quick
    report = ES.evaluate("translator", limit=1, log=lambda *_: None)
    styles = report["styles"]
    assert report["held_out_takes"] == 1 and styles == 19
    rows = report["rows"]
    assert rows["real held-out"]["n"] == 1 and rows["unchanged"]["n"] == styles
    assert rows["translator"]["n"] == styles  # the take sent to every style
    pairs = rows["translator (pairs with a real target)"]["n"]
    assert pairs == rows["real target"]["n"] and 0 < pairs < styles
    assert rows["unchanged"]["turning_error_deg"] == 0.0  # the content against itself
    for row in rows.values():  # merging names can only add hits
        if row["n"]:
            assert row["content_accuracy_all_takes_merged"] >= row["content_accuracy_all_takes"]
            assert 0.0 <= row["content_accuracy_unseen_takes"] <= 1.0
    assert rows["translator"]["foot_skating_cm_s"] >= 0.0
    assert sum(r["n"] for r in report["per_style"].values()) == styles
    assert "| translator |" in ES.markdown(report)
    recorded = recorded_evaluation(ES.record_in_manifest, report, tmp_path)
    assert recorded["translator_held_out_takes"]["held_out_takes"] == 1


def test_transfers_at_a_strength_are_the_apis_and_only_the_translator_takes_one():
    """``--strength`` judges the translator's transfers as the API makes them at that
    strength: at 0 every target keeps the content's own style code and is not time-warped."""
    engine, _, _ = ES.load_engine("translator")
    canon = retarget.to_canonical(bvh.load(FIXTURE))
    styles = ES.style_names("translator", engine)[:2]
    kept = [ES.transfer("translator", engine, canon, s, strength=0.0) for s in styles]
    full = [ES.transfer("translator", engine, canon, s) for s in styles]
    assert kept[0].num_frames == kept[1].num_frames == canon.num_frames
    np.testing.assert_allclose(kept[0].lrot, kept[1].lrot)
    assert full[0].num_frames != full[1].num_frames or not np.allclose(full[0].lrot, full[1].lrot)
    with pytest.raises(ValueError, match="strength"):
        ES.transfer("fast", None, canon, styles[0], strength=0.5)
    for argv in (
        ["fast", "--strength", "0.5"],
        ["translator", "--strength", "1.5"],
        ["translator", "--strength", "0.5", "--manifest"],
    ):
        with pytest.raises(SystemExit):
            ES.main(argv)

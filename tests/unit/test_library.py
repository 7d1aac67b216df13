"""A studio's library (training.library) and its check (training.library_check), on real
clips: the CMU fixture presented on other tools' rigs (tests/rigs.py) and as a glTF
character (tests/gltf_files.py), labelled only in labels.csv."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motion import bvh
from tests import rigs
from tests.gltf_files import character_glb
from training import library as L
from training import library_check as LC

REPO = Path(__file__).resolve().parents[2]
# where the foreign evaluation's clips are cached for every run (this module's tests keep
# their libraries' caches apart)
SHARED_CACHE = Path(os.environ.get("MOTION_CACHE_DIR", REPO / "cache"))


def _slowed(motion, fps: float):
    """The fixture's walk played at ``fps`` (60 frames: 4 s at 15 fps, 3 s at 20 fps)."""
    return motion.replace(fps=fps)


def _reversed(motion):
    return motion.replace(lrot=motion.lrot[::-1].copy(), lpos=motion.lpos[::-1].copy())


def write_library(
    root: Path, rows: list[tuple[str, object, str, str]], column: str = "", values=None
) -> Path:
    """``rows``: (file, motion or bytes, style, content); files named without labels;
    ``column``: one more, with ``values`` per file."""
    root.mkdir(parents=True, exist_ok=True)
    with open(root / "labels.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["file", "style", "content", *([column] if column else [])])
        for file, clip, style, content in rows:
            path = root / file
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(clip, bytes):
                path.write_bytes(clip)
            elif clip is not None:
                bvh.save(clip, path)
            w.writerow([file, style, content, *([values[file]] if column else [])])
    return root


def good_rows() -> list:
    """Two styles (the walk played slow and brisk) x two actions (forward, backward), two
    takes each, on five rigs: CMU, Mixamo (ZXY), Unreal (rotated frames, extra root),
    Biped (Z up, centimetres) and a glTF character."""
    walk = rigs.load_fixture()
    presentations = [
        lambda m: m,
        lambda m: rigs.with_channels(rigs.renamed(m, rigs.CMU_TO_MIXAMO), "ZXY"),
        lambda m: rigs.with_extra_root(rigs.random_frames(rigs.renamed(m, rigs.CMU_TO_UNREAL), 1)),
        lambda m: rigs.scaled(rigs.z_up(rigs.renamed(m, rigs.CMU_TO_BIPED)), 2.54),
    ]
    rows, k = [], 0
    for style, fps in (("slow", 15.0), ("brisk", 20.0)):
        for content, base in (("forward", walk), ("backward", _reversed(walk))):
            for take in range(2):
                motion = _slowed(base, fps)
                k += 1
                if style == "brisk" and content == "backward" and take == 1:
                    rows.append((f"clips/c{k:02d}.glb", character_glb(motion), style, content))
                else:
                    show = presentations[k % len(presentations)]
                    rows.append((f"clips/c{k:02d}.bvh", show(motion), style, content))
    return rows


@pytest.fixture(scope="module")
def good_library(tmp_path_factory) -> Path:
    """:func:`good_rows`, one forward take of each style held out."""
    held = {r[0]: "yes" if r[0] in ("clips/c02.bvh", "clips/c06.bvh") else "no"
            for r in good_rows()}  # fmt: skip
    return write_library(tmp_path_factory.mktemp("lib") / "studio", good_rows(), "held_out", held)


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MOTION_CACHE_DIR", str(tmp_path / "cache"))


def test_a_good_library_maps_every_rig_and_lists_its_pairs(good_library):
    report = LC.check(good_library, measure=False)
    assert report.problems == []
    assert report.clips == 8
    methods = {g["method"] for g in report.rigs}
    assert methods <= {"names", "structure"} and len(report.rigs) >= 4
    assert all(0.0 <= g["confidence"] <= 1.0 for g in report.rigs)
    assert {g["up"] for g in report.rigs} >= {"Y", "Z"}
    assert report.pairs == {"backward": ["brisk", "slow"], "forward": ["brisk", "slow"]}
    assert report.styles["slow"] | {"contents": None} == {
        "takes": 4,
        "held_out": 1,
        "contents": None,
        "shared_contents": ["backward", "forward"],
    }
    text = LC.render(report)
    assert "ready to train" in text and "forward: brisk, slow" in text


def test_labels_come_from_the_table_and_clips_are_canonical(good_library):
    clips = L.read_library(good_library)
    assert [c.style for c in clips] == ["slow"] * 4 + ["brisk"] * 4
    assert [c.content for c in clips] == ["forward", "forward", "backward", "backward"] * 2
    assert all(c.lrot.shape[1] == 22 for c in clips)
    # 60 frames at 15 fps span 59 / 15 s: 119 frames at 30 fps
    assert [c.num_frames for c in clips[:2]] == [119, 119]
    assert clips[0].take == "clips/c01" and clips[0].extra["file"] == "clips/c01.bvh"
    assert all(c.extra["mirror_ok"] for c in clips)
    # every presentation of one performance lands on the same canonical poses
    same = [c for c in clips if c.style == "slow" and c.content == "forward"]
    np.testing.assert_allclose(same[0].root, same[1].root, atol=2e-3)


def test_the_cache_follows_the_content(tmp_path):
    root = write_library(tmp_path / "lib", good_rows()[:4])
    first = L.read_library(root)
    assert {c.style for c in first} == {"slow"}
    labels = (root / "labels.csv").read_text().replace("slow", "calm")
    (root / "labels.csv").write_text(labels)
    assert {c.style for c in L.read_library(root)} == {"calm"}


def test_held_out_takes_by_default_and_by_label(tmp_path):
    rows = [(f"t{i}.bvh", None, "s", "walk") for i in range(40)]
    root = write_library(tmp_path / "lib", rows)
    for i in range(40):
        (root / f"t{i}.bvh").write_text("")
    library, problems = L.read_labels(root)
    assert problems == []
    held = [r.take for r in library.rows if r.held_out]
    assert held == [f"t{i}" for i in range(40) if L.held_out_by_rule(f"t{i}")] and held
    given = {f"t{i}.bvh": "yes" if i == 3 else "no" for i in range(40)}
    root = write_library(tmp_path / "lib2", rows, "held_out", given)
    for i in range(40):
        (root / f"t{i}.bvh").write_text("")
    library, problems = L.read_labels(root)
    assert problems == []
    assert [r.take for r in library.rows if r.held_out] == ["t3"]


def test_a_broken_library_names_each_problem_and_exits_non_zero(tmp_path):
    rows = good_rows()[:4] + good_rows()[4:6]  # slow: 4 takes; brisk: forward only
    # a rig with no humanoid in it: a four-joint chain
    chain = rigs.load_fixture()
    keep = [0, 1, 2, 3]
    sk = chain.skeleton
    from motion.skeleton import Motion, Skeleton

    stick = Motion(
        Skeleton(("a", "b", "c", "d"), sk.parents[keep], sk.offsets[keep],
                 tuple(sk.channels[j] for j in keep), {}),
        chain.fps, chain.lrot[:, keep], chain.lpos[:, keep],
    )  # fmt: skip
    rows += [
        ("clips/stick.bvh", stick, "brisk", "backward"),
        ("clips/gone.bvh", None, "brisk", "backward"),
        ("clips/lonely.bvh", _slowed(rigs.load_fixture(), 15.0), "lonely", "forward"),
    ]
    root = write_library(tmp_path / "broken", rows)
    result = subprocess.run(
        [sys.executable, "-m", "model_export.train_library", "check", str(root)],
        capture_output=True, text=True, cwd=REPO, timeout=300,
    )  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    problems = [line for line in result.stdout.splitlines() if line.startswith("problem:")]
    assert any("clips/gone.bvh does not exist" in p for p in problems), problems
    assert any("clips/stick.bvh" in p and "cannot be mapped" in p for p in problems), problems
    assert any("style lonely has 1 take" in p for p in problems), problems
    assert len(problems) == 3, problems
    assert "estimate" not in result.stdout  # nothing measured or trained


def test_a_style_sharing_no_action_is_a_problem(tmp_path):
    rows = good_rows()
    rows = [r if r[2] == "slow" else (r[0], r[1], r[2], "dance") for r in rows]
    report = LC.check(write_library(tmp_path / "lib", rows), measure=False)
    assert any("style brisk shares no action" in p for p in report.problems)
    assert any("style slow shares no action" in p for p in report.problems)


def test_rows_that_cannot_be_read_are_problems(tmp_path):
    root = tmp_path / "lib"
    root.mkdir()
    (root / "a.bvh").write_text("HIERARCHY\nROOT Hips\n{ nonsense")
    (root / "b.fbx").write_bytes(b"Kaydara FBX Binary")
    (root / "labels.csv").write_text(
        "file,style,content,mirror_ok\na.bvh,x,walk,maybe\nb.fbx,x,walk,\n../c.bvh,y,walk,\n"
        ",y,walk,\n"
    )
    report = LC.check(root, measure=False)
    text = "\n".join(report.problems)
    assert "mirror_ok is 'maybe'" in text
    assert "b.fbx: FBX is not read by training yet" in text
    assert "../c.bvh lies outside the library folder" in text
    assert "line 5: empty file" in text
    assert "a.bvh: cannot be read" in text
    library, _ = L.read_labels(tmp_path / "nowhere")
    assert library.rows == [] and not LC.check(tmp_path / "nowhere", measure=False).ok


def test_the_estimate_is_measured_here(good_library):
    report = LC.check(good_library, translator_steps=1000)
    e = report.estimate
    assert e["steps_per_cpu_s"]["translator"] > 0 and e["steps_per_cpu_s"]["fast"] > 0
    assert e["cpu_hours"] > e["hours_here"] > e["hours_gpu"] > 0
    assert e["fast_steps"] == 2 * LC.FAST_STEPS


def _train_argv(library: Path, tmp_path: Path) -> list[str]:
    return [
        str(library), "-o", str(tmp_path / "models" / "studio"),
        "--licence", "CC0 1.0 (the studio's own capture)", "--work", str(tmp_path / "work"),
        "--runs", str(tmp_path / "runs"), "--device", "cpu", "--jobs", "1",
    ]  # fmt: skip


@pytest.fixture(scope="module")
def trained_studio(good_library, tmp_path_factory) -> tuple[list[str], Path]:
    """:func:`good_library` trained by the one command, a few steps of each stage: its
    arguments and the folder it wrote under (models/studio, work, runs)."""
    pytest.importorskip("torch")
    from model_export import train_library as TL

    tmp = tmp_path_factory.mktemp("trained")
    argv = _train_argv(good_library, tmp)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("MOTION_SMOKE", "1")  # a few steps of each
        patch.setenv("MOTION_CACHE_DIR", str(tmp / "cache"))
        assert TL.main(argv) == 0
    return argv, tmp


@pytest.mark.slow
def test_one_command_trains_both_families_that_the_service_loads(
    good_library, trained_studio, monkeypatch
):
    from model_export import train_library as TL
    from training.judges import load_engine, transfer

    monkeypatch.setenv("MOTION_SMOKE", "1")
    argv, tmp_path = trained_studio
    out = tmp_path / "models" / "studio"
    models = {m["name"]: m for m in json.loads((out / "manifest.json").read_text())["models"]}
    assert set(models) == {"translator-studio", "fast-studio"}
    content_hash = L.read_labels(good_library)[0].content_hash()
    for entry in models.values():
        assert entry["licence"] == "CC0 1.0 (the studio's own capture)"
        assert entry["extra"]["library"] == "studio"
        assert entry["extra"]["library_sha256"] == content_hash
        assert [s["name"] for s in entry["extra"]["schedule"]] == ["paired"]
    assert set(models["translator-studio"]["metrics"]["validation"]) >= {"rot", "pos"}
    assert sorted(models["fast-studio"]["extra"]["styles"]) == ["brisk", "slow"]
    assert list((tmp_path / "runs" / "translator" / "paired").glob("events.out.tfevents.*"))
    canon = L.read_library(good_library)[0].motion
    for family in ("translator", "fast"):
        engine, entry, _ = load_engine(family, out)
        assert entry.licence.startswith("CC0")
        out_motion = transfer(family, engine, canon, "brisk", time_warp=False)
        assert out_motion.num_frames == canon.num_frames
        assert np.isfinite(out_motion.lrot).all()
    # run again: everything is done, nothing trains
    stamp = (tmp_path / "work" / "translator.pt").stat().st_mtime_ns
    assert TL.main(argv) == 0
    assert (tmp_path / "work" / "translator.pt").stat().st_mtime_ns == stamp


def _few_steps(monkeypatch) -> list[tuple[int, list[str]]]:
    """The style judge's classifiers trained 3 steps of one seed; the clips (mirrors
    included) and labels each one is given."""
    from training.judges import ConvClipClassifier

    given = []
    train = ConvClipClassifier.__init__

    def recording(self, features, labels, seeds=(0,), steps=3):
        given.append((len(features), list(labels)))
        train(self, features, labels, seeds, steps)

    monkeypatch.setattr(ConvClipClassifier, "__init__", recording)
    return given


def test_a_librarys_judge_knows_its_styles_and_is_checked_on_its_held_out_takes(
    good_library, monkeypatch
):
    from dataclasses import replace

    from training import foreign_judge as FJ

    given = _few_steps(monkeypatch)
    clips = L.read_library(good_library)
    judge = FJ.train_library_judge(clips)
    assert judge.classes == ["brisk", "slow"]  # the table's names, none merged
    # the judge: every take and its mirror; its twin: all but the two held out
    assert [n for n, _ in given] == [16, 12]
    assert sorted(given[1][1]) == ["brisk"] * 6 + ["slow"] * 6
    assert [(h["take"], h["style"]) for h in judge.held_out] == [
        ("clips/c02", "slow"),
        ("clips/c06", "brisk"),
    ]
    reference = FJ.held_out_reference(judge)
    assert reference["n"] == 2 and set(reference["recall"]) == {"brisk", "slow"}
    assert 0.0 <= reference["top1"] <= reference["top3"] == 1.0  # two classes
    # a take whose mirror is no take of its style is not mirrored
    given.clear()
    unmirrored = [replace(c, extra={**c.extra, "mirror_ok": c.take != "clips/c01"}) for c in clips]
    FJ.train_library_judge(unmirrored)
    assert [n for n, _ in given] == [15, 11]
    nothing_held = [replace(c, extra={**c.extra, "held_out": False}) for c in clips]
    with pytest.raises(ValueError, match="holds no take out"):
        FJ.train_library_judge(nothing_held)
    brisk_held = [replace(c, extra={**c.extra, "held_out": c.style == "brisk"}) for c in clips]
    with pytest.raises(ValueError, match="brisk have only held-out takes"):
        FJ.train_library_judge(brisk_held)


def test_eval_foreign_with_a_library_needs_the_models_trained_on_it(good_library, capsys):
    from training import eval_foreign as EF

    with pytest.raises(SystemExit) as stop:
        EF.main(["--library", str(good_library)])
    assert stop.value.code == 2 and "--library needs --models-dir" in capsys.readouterr().err


@pytest.mark.slow
def test_eval_foreign_judges_a_librarys_models_by_its_own_takes(
    good_library, trained_studio, tmp_path, monkeypatch
):
    """``make eval-foreign LIBRARY=... MODELS=...`` on one foreign item of the test half
    (a judge of a few steps), then ``make record-evaluations`` with the same two: the
    figures land in the library's models' own entries; the shipped models, whose styles
    the library lacks, are refused before anything trains."""
    import shutil

    from model_export import evaluations as EV
    from service.manifest import load_manifest
    from tests.conftest import data_path
    from training import eval_foreign as EF
    from training import foreign_report as FR

    for folder in ("cmu-31", "xia", "cmu-dance-43", "cmu-dance-3dsmax"):
        data_path(folder)
    monkeypatch.setenv("MOTION_CACHE_DIR", str(SHARED_CACHE))
    given = _few_steps(monkeypatch)
    _, trained = trained_studio
    models = tmp_path / "studio"
    shutil.copytree(trained / "models" / "studio", models)
    with pytest.raises(ValueError, match=r"translator-.* serves style\(s\) .*active"):
        EF.evaluate(("test",), ("translator",), library=good_library, log=lambda *_: None)
    assert given == []
    families = ("translator", "fast")
    cache = tmp_path / "judges"
    report = EF.evaluate(
        ("test",), families, cache, limit=1, log=lambda *_: None,
        library=good_library, models_dir=models,
    )["test"]  # fmt: skip
    assert report["styles"] == ["brisk", "slow"] and report["items"] == 1
    content_hash = L.read_labels(good_library)[0].content_hash()
    assert report["library"] == {"name": "studio", "sha256": content_hash, "takes": 8}
    assert "real_bandai" not in report
    reference = report["real_library"]["held_out_takes"]
    assert reference["n"] == 2 and report["real_library"]["spread"] > 0.0
    for family in families:
        figures = report["families"][family]
        assert figures["model_name"] == f"{family}-studio"
        assert figures["names_sent"] == ["brisk", "slow"] and figures["n"] == 2
        assert set(figures["predicted_share"]) <= {"brisk", "slow"}
        assert figures["held_out_jitter"]["takes"] == 2
    text = FR.markdown(report)
    assert "2 styles of library studio" in text and "real studio, held-out takes" in text
    assert "leave-action-out" not in text and "the library's held-out takes" in text
    # a second run takes the judge from the cache
    assert len(given) == 2 and list(cache.glob("library-judge-*.pkl"))
    EF.evaluate(
        ("test",), ("fast",), cache, limit=1, log=lambda *_: None,
        library=good_library, models_dir=models,
    )  # fmt: skip
    assert len(given) == 2
    EV.main([str(_written(report, tmp_path)), "--models-dir", str(models)])
    for family in families:
        entry = next(m for m in load_manifest(models).models if m.name == f"{family}-studio")
        recorded = entry.metrics["evaluation"]["foreign_test_half"]
        assert recorded["top1"] == report["families"][family]["top1"]
        assert recorded["library"] == "studio" and recorded["library_sha256"] == content_hash
        assert recorded["real_held_out_takes_top1"] == reference["top1"]
        assert "--library studio" in recorded["by"] and "16 merged" not in recorded["by"]


def _written(report: dict, folder: Path) -> Path:
    path = folder / "foreign-test.json"
    path.write_text(json.dumps(report))
    return path


@pytest.mark.slow
def test_a_stopped_stage_resumes_to_the_weights_of_an_uninterrupted_one(
    good_library, tmp_path, monkeypatch
):
    torch = pytest.importorskip("torch")
    from model_export import train_library as TL
    from training.translator import fit
    from training.translator.schedule import load_schedule

    monkeypatch.setenv("MOTION_SMOKE", "1")
    stage = load_schedule()[0] | {"flags": load_schedule()[0]["flags"] | {"channels": 32}}
    common = ["--library", str(good_library), "--log", str(tmp_path / "runs")]
    whole = tmp_path / "whole.pt"
    fit.main(TL.translator_flags(stage, whole, []) + common)
    parted = tmp_path / "parted.pt"
    # stopped after its first step (out of time), then continued as the command would
    fit.main(TL.translator_flags(stage, parted, []) + common + ["--max-minutes", "1e-9"])
    first = torch.load(parted, weights_only=False)
    assert first["step"] == 1 and first["stages"] == [] and first["stage"] == "paired"
    flags = TL.translator_flags(stage, parted, [])
    assert "--resume" in flags
    # a weights-only copy (as committed, no .state) continues from its weights and step
    alone = tmp_path / "alone.pt"
    alone.write_bytes(parted.read_bytes())
    fit.main(TL.translator_flags(stage, alone, []) + common)
    continued = torch.load(alone, weights_only=False)
    assert continued["step"] == 3 and continued["stages"] == ["paired"]
    fit.main(flags + common)
    a = torch.load(whole, weights_only=False)
    b = torch.load(parted, weights_only=False)
    assert a["step"] == b["step"] == 3 and b["stages"] == ["paired"]
    for key, value in a["weights"].items():
        assert torch.equal(value, b["weights"][key]), key


def _step(checkpoint: Path) -> int:
    import torch

    return torch.load(checkpoint, weights_only=False)["step"] if checkpoint.exists() else 0


@pytest.mark.slow
def test_a_run_killed_at_a_random_step_resumes_to_the_weights_of_an_uninterrupted_one(
    good_library, tmp_path
):
    """The schedule's stage made short (24 steps of 32 channels, a checkpoint after every
    step, so that the kill may land anywhere, a write included), killed with SIGKILL at a
    random step, then started again as the one command starts it: it ends with the weights
    of a run never stopped, to the bit."""
    import random
    import signal
    import time

    torch = pytest.importorskip("torch")
    from model_export import train_library as TL
    from training.translator import fit
    from training.translator.schedule import load_schedule

    short = {"channels": 32, "steps": 24, "batch": 8, "val-every": 8, "checkpoint-minutes": 0}
    stage = load_schedule()[0]
    stage = stage | {"flags": stage["flags"] | short}
    common = ["--library", str(good_library), "--log", str(tmp_path / "runs")]
    whole = tmp_path / "whole.pt"
    fit.main(TL.translator_flags(stage, whole, []) + common)
    killed = tmp_path / "killed.pt"
    at = random.randrange(2, 16)
    run = subprocess.Popen(
        [sys.executable, "-m", "training.translator.fit",
         *TL.translator_flags(stage, killed, []), *common],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.time() + 300
        while _step(killed) < at:
            assert run.poll() is None and time.time() < deadline, f"no step {at} to kill at"
            time.sleep(0.02)
        run.send_signal(signal.SIGKILL)
    finally:
        run.kill()
        run.wait()
    stopped = torch.load(killed, weights_only=False)
    assert at <= stopped["step"] < 24 and stopped["stages"] == [], (at, stopped["step"])
    flags = TL.translator_flags(stage, killed, [])
    assert "--resume" in flags
    fit.main(flags + common)
    a = torch.load(whole, weights_only=False)
    b = torch.load(killed, weights_only=False)
    assert a["step"] == b["step"] == 24 and b["stages"] == ["paired"]
    for key, value in a["weights"].items():
        assert torch.equal(value, b["weights"][key]), (key, at, stopped["step"])


def test_a_checkpoint_state_ahead_of_its_payload_resumes_from_the_state(good_library, tmp_path):
    """Killed between the two writes of a checkpoint (the state is written first), a run
    resumes from the state's weights and step, not from the older payload's."""
    torch = pytest.importorskip("torch")
    from model_export import train_library as TL
    from training.translator import fit
    from training.translator.schedule import load_schedule

    short = {"channels": 32, "steps": 3, "batch": 4, "val-every": 10, "checkpoint-minutes": 0}
    stage = load_schedule()[0]
    stage = stage | {"flags": stage["flags"] | short}
    common = ["--library", str(good_library), "--log", str(tmp_path / "runs")]
    whole = tmp_path / "whole.pt"
    fit.main(TL.translator_flags(stage, whole, []) + common + ["--max-minutes", "1e-9"])
    older = whole.read_bytes()  # the payload after step 1
    fit.main(TL.translator_flags(stage, whole, []) + common + ["--max-minutes", "1e-9"])
    state = torch.load(f"{whole}.state", weights_only=False)
    assert state["step"] == 2
    whole.write_bytes(older)  # as if killed before the payload of step 2 was written
    fit.main(TL.translator_flags(stage, whole, []) + common)
    again = tmp_path / "again.pt"
    fit.main(TL.translator_flags(stage, again, []) + common)
    a = torch.load(whole, weights_only=False)
    b = torch.load(again, weights_only=False)
    assert a["step"] == b["step"] == 3
    for key, value in a["weights"].items():
        assert torch.equal(value, b["weights"][key]), key


@pytest.mark.slow
def test_the_bandai_library_holds_what_training_read_by_file_names(data_dir, tmp_path):
    """training.bandai_library's labels.csv: the clips, labels and held-out takes that
    training.data.load_bandai and the name rule gave, in its order (so the shipped
    schedule replays on the library)."""
    from motion.styles import canonical_style
    from training import bandai_library
    from training import data as D
    from training.bandai_library import held_out_take

    root = bandai_library.write(tmp_path / "bandai", root=data_dir)
    library, problems = L.read_labels(root)
    assert problems == [] and len(library.rows) == 454
    by_names = D.load_bandai(data_dir)
    clips = L.read_library(root)
    assert [c.name for c in clips] == [c.name for c in by_names]
    for a, b in zip(by_names, clips, strict=True):
        assert (b.take, b.style, b.content) == (a.take, canonical_style(a.style), a.content)
        assert b.extra["held_out"] == held_out_take(a.name)
        np.testing.assert_array_equal(a.lrot, b.lrot)
        np.testing.assert_array_equal(a.root, b.root)
    assert sum(c.extra["held_out"] for c in clips) == 29


@pytest.mark.slow
def test_two_processes_train_one_translator_under_torchrun(good_library, tmp_path):
    """torchrun, gloo, 2 CPU processes: each draws its own batches (their random states
    are both kept), the averaged gradients keep their weights equal to the last bit."""
    torch = pytest.importorskip("torch")
    torchrun = Path(sys.executable).with_name("torchrun")
    if not torchrun.exists():
        pytest.skip("torchrun is not installed beside this Python")
    out = tmp_path / "t.pt"
    env = {**__import__("os").environ, "MOTION_SMOKE": "1", "PYTHONPATH": str(REPO)}
    result = subprocess.run(
        [str(torchrun), "--nproc_per_node", "2", "-m", "training.translator.fit",
         "--library", str(good_library), "--out", str(out), "--runs", str(tmp_path / "runs"),
         "--channels", "32", "--stage", "paired"],
        capture_output=True, text=True, cwd=REPO, timeout=600, env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "2 processes, weights apart by at most 0.00e+00" in result.stdout
    payload = torch.load(out, weights_only=False)
    assert payload["processes"] == 2 and payload["stages"] == ["paired"]
    rngs = torch.load(f"{out}.state", weights_only=False)["rngs"]
    assert len(rngs) == 2 and rngs[0] != rngs[1]


@pytest.mark.slow
def test_two_processes_train_both_families_by_the_one_command(good_library, tmp_path):
    """torchrun, gloo, 2 CPU processes through the one command: the translator, then each
    fast network trained by both processes together (each on its share of the clips, the
    weights equal to the last bit), exported once by the first."""
    torch = pytest.importorskip("torch")
    torchrun = Path(sys.executable).with_name("torchrun")
    if not torchrun.exists():
        pytest.skip("torchrun is not installed beside this Python")
    env = {**__import__("os").environ, "MOTION_SMOKE": "1", "PYTHONPATH": str(REPO),
           "MOTION_CACHE_DIR": str(tmp_path / "cache")}  # fmt: skip
    result = subprocess.run(
        [str(torchrun), "--nproc_per_node", "2", "-m", "model_export.train_library",
         *_train_argv(good_library, tmp_path)],
        capture_output=True, text=True, cwd=REPO, timeout=900, env=env,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert result.stdout.count("fast networks: 2 of 2 styles to train") == 1
    assert torch.load(tmp_path / "work" / "translator.pt", weights_only=False)["processes"] == 2
    for style in ("brisk", "slow"):
        saved = torch.load(tmp_path / "work" / "fast" / f"style_{style}.pt", weights_only=False)
        assert saved["result"]["processes"] == 2
    out = tmp_path / "models" / "studio"
    models = {m["name"]: m for m in json.loads((out / "manifest.json").read_text())["models"]}
    assert set(models) == {"translator-studio", "fast-studio"}
    assert sorted(models["fast-studio"]["extra"]["styles"]) == ["brisk", "slow"]

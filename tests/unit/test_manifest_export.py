"""``model_export.manifest``: entries are hashed and validated; evaluation figures land in
the entry of the model they were measured on, and only if it is still that model."""

from __future__ import annotations

import json

import pytest

from model_export import manifest as MF
from service.manifest import load_manifest, sha256_of


def entry(version: str) -> dict:
    return {
        "name": "translator-test",
        "family": "translator",
        "version": version,
        "files": ["translator/weights.bin"],
        "graphs": {"decoder": MF.graph_spec("translator/weights.bin", 17, [], [])},
        "licence": "test",
        "metrics": {"rec_pos_cm": 3.2},
    }


@pytest.fixture()
def models(tmp_path):
    (tmp_path / "translator").mkdir()
    (tmp_path / "translator" / "weights.bin").write_bytes(b"weights")
    MF.put_entry(entry("1"), tmp_path)
    return tmp_path


def test_entries_are_hashed(models):
    (model,) = load_manifest(models).models
    assert model.files[0].sha256 == sha256_of(models / "translator" / "weights.bin")


def test_evaluation_is_recorded_beside_the_training_metrics(models):
    figures = {"rows": {"translator": {"style_accuracy": 0.379}}}
    MF.put_evaluation("translator-test", "1", "translator_held_out_takes", figures, models)
    MF.put_evaluation("translator-test", "1", "fast_held_out_takes", {"rows": {}}, models)
    (model,) = load_manifest(models).models
    assert model.metrics["rec_pos_cm"] == 3.2
    assert model.metrics["evaluation"]["translator_held_out_takes"] == figures
    assert set(model.metrics["evaluation"]) == {"translator_held_out_takes", "fast_held_out_takes"}


def test_figures_of_another_version_are_refused(models):
    before = (models / "manifest.json").read_text()
    with pytest.raises(ValueError, match="version '1', not '2'"):
        MF.put_evaluation("translator-test", "2", "translator_held_out_takes", {}, models)
    with pytest.raises(ValueError, match="'nope' at version None"):
        MF.put_evaluation("nope", "1", "translator_held_out_takes", {}, models)
    assert (models / "manifest.json").read_text() == before


def test_what_an_export_measures_lands_in_its_own_entry(models):
    MF.update_entry("translator-test", "1", {"output_smoothing": 1.0}, {"jerk": 0.9}, models)
    (model,) = load_manifest(models).models
    assert model.extra["output_smoothing"] == 1.0
    assert model.metrics == {"rec_pos_cm": 3.2, "jerk": 0.9}
    with pytest.raises(ValueError, match="version '1', not '2'"):
        MF.update_entry("translator-test", "2", {"output_smoothing": 2.0}, models_dir=models)
    assert load_manifest(models).models[0].extra["output_smoothing"] == 1.0


def test_a_change_to_what_a_model_outputs_is_a_new_version(models):
    MF.put_evaluation("translator-test", "1", "foreign_test_half", {"top1": 0.8}, models)
    MF.update_entry("translator-test", "1", {"output_smoothing": 2.0}, models_dir=models)
    assert "evaluation" in load_manifest(models).models[0].metrics  # same outputs, same figures
    MF.update_entry("translator-test", "1", {"output_smoothing": 1.0}, None, models, "1b")
    (model,) = load_manifest(models).models
    assert model.version == "1b" and model.extra["output_smoothing"] == 1.0
    assert "evaluation" not in model.metrics


def test_a_new_export_drops_the_old_evaluation(models):
    MF.put_evaluation("translator-test", "1", "translator_held_out_takes", {"rows": {}}, models)
    MF.put_entry(entry("2"), models)
    doc = json.loads((models / "manifest.json").read_text())
    assert "evaluation" not in doc["models"][0]["metrics"]


def test_dance_evaluation_records_its_summary(models):
    from model_export import evaluations as EV
    from training.measuring_machine import measuring_machine

    report = {
        "model_name": "translator-test", "model_version": "1", "seeds": 3,
        "songs": {"a": {}, "b": {}},
        "beat_alignment": {"generated": {"bas": 0.55, "chance": 0.27, "n": 6}},
        "foot_sliding_cm_s": {"real": 9.0, "generated": 6.0},
        "foot_contact_score": {"real": 0.9, "generated": 0.8},
        "feature_distances": {"test": {"kinetic": 1.5}, "dev": {"kinetic": 9.9}},
        "speed_against_genre": {"slowest": {"song": "a", "share": 0.4}, "under": 1, "n": 8},
        "genre_accuracy": {"generated": 0.25, "real_held_out": 1.0, "chance": 0.25,
                           "confusion": [[1]],
                           "by_half": {"dev": {"generated": 0.5, "confusion": [[1]]},
                                       "test": {"generated": 0.75, "confusion": [[1]]}}},
        "ten_minutes": {"frames": 18000, "per_30s_min": 26.3},
        "generated_set": {"songs": [
            {"f_measure": 0.9, "passes": True, "dances": [{"stalls": 0}]},
            {"f_measure": 0.7, "passes": False, "dances": [{"stalls": 2}]}]},
        "shared_songs": {"x": {"bas": 0.6, "chance": 0.3, "stalls": 0, "passes": True},
                         "y": {"bas": 0.2, "chance": 0.3, "stalls": 1, "passes": False}},
        "machine": measuring_machine(),
    }  # fmt: skip
    EV.record_dance(report, models)
    (model,) = load_manifest(models).models
    figures = model.metrics["evaluation"]["held_out_songs"]
    assert figures["songs"] == 2 and figures["beat_alignment"]["generated"]["bas"] == 0.55
    assert figures["ten_minutes"]["frames"] == 18000
    assert figures["generated_set"] == {"songs": 2, "tracker_f_measure": 0.8, "passing": 1,
                                        "stalls": 2}  # fmt: skip
    assert figures["shared_songs"]["songs"] == 2 and figures["shared_songs"]["stalls"] == 1
    assert figures["shared_songs"]["passing_reference_beats"] == 1
    assert figures["feature_distances_test_half"] == {"kinetic": 1.5}
    assert figures["genre_accuracy"] == {
        "generated": 0.25,
        "real_held_out": 1.0,
        "chance": 0.25,
        "test_half": {"generated": 0.75},
    }
    assert figures["foot_contact_score"]["generated"] == 0.8
    assert figures["speed_against_genre"]["under"] == 1
    assert "cores; BLAS kernels:" in figures["machine"]
    with pytest.raises(ValueError, match="not '2'"):
        EV.record_dance(report | {"model_version": "2"}, models)


def test_a_second_export_on_one_day_is_a_new_version(models):
    import datetime as dt

    today = dt.date.today().isoformat()
    assert MF.dated_version("translator-test", models) == f"{today}.1"  # "1" is not today's
    assert MF.dated_version("not-there", models) == f"{today}.1"
    MF.put_entry(entry(f"{today}.1"), models)
    assert MF.dated_version("translator-test", models) == f"{today}.2"
    MF.put_entry(entry(f"{today}.9"), models)
    assert MF.dated_version("translator-test", models) == f"{today}.10"

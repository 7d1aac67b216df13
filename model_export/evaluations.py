"""The one step that records evaluations in the manifest: an evaluation writes its report as
JSON (``training.eval_foreign``: ``runs/eval/foreign-test.json``; ``training.eval_dance
--json``; ``training.game_invariants --json``), and this puts its headline figures into the judged models' entries
(``metrics.evaluation``), refused for another version of a model than the one judged.

    python -m model_export.evaluations REPORT.json [...] [--models-dir DIR]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from model_export import manifest as MF
from model_export.manifest import put_evaluation
from training import eval_foreign as EF


def record_foreign(report: dict, models_dir: Path) -> None:
    """The test half's headline figures into each judged model's manifest entry
    (``metrics.evaluation.foreign_test_half``): recognition, spread, content kept, foot
    sliding and anatomy (knees and elbows bent backwards, the fastest joint), the last two
    beside the real takes' and, for anatomy, the content's own; with the reference of the
    judge that gave them: Bandai's leave-action-out, or a library's held-out takes
    (``eval_foreign --library``)."""
    if report["half"] != "test":
        raise ValueError(f"the manifest records the test half, not {report['half']!r}")
    keep = (
        "n",
        "top1",
        "top3",
        "top1_mean_per_style",
        "recall",
        "most_predicted",
        "most_predicted_share",
        "spread_ratio",
        "content_kept",
        "content_kept_share",
        "foot_sliding_cm_s",
        "intervals_90",
        "anatomy",
    )
    if "library" in report:
        library = report["library"]
        real = report["real_library"]
        judged_on = {
            "library": library["name"],
            "library_sha256": library["sha256"],
            "real_held_out_takes_top1": real["held_out_takes"]["top1"],
            "real_held_out_takes_most_predicted_share": real["held_out_takes"][
                "most_predicted_share"
            ],
        }
        by = (
            f"python -m training.eval_foreign --library {library['name']} (a judge trained "
            f"on its {library['takes']} real takes, {len(report['styles'])} styles)"
        )
    else:
        real = report["real_bandai"]
        judged_on = {"real_leave_action_out_top1": real["leave_action_out"]["top1"]}
        by = "python -m training.eval_foreign (16 merged styles)"
    for family, figures in report["families"].items():
        put_evaluation(
            figures["model_name"],
            figures["model_version"],
            EF.EVALUATION_KEY.get(family, "foreign_test_half"),
            {
                **{k: figures[k] for k in keep},
                "items": report["items"],
                **judged_on,
                "real_foot_sliding_cm_s": real["foot_sliding_cm_s"],
                "real_anatomy": real["anatomy"],
                "content_anatomy": report["unchanged"]["anatomy"],
                "measured": report.get("measured", ""),
                "machine": report["machine"],
                "by": by,
            },
            models_dir,
        )


def record_dance(report: dict, models_dir: Path) -> None:
    """The report's summary figures into its model's manifest entry (refused for another
    version of the model; a new export drops them)."""
    gen = report["generated_set"]["songs"]
    shared = report["shared_songs"]
    figures = {
        "songs": len(report["songs"]),
        "seeds": report["seeds"],
        "beat_alignment": report["beat_alignment"],
        "foot_sliding_cm_s": report["foot_sliding_cm_s"],
        "foot_contact_score": report["foot_contact_score"],
        "feature_distances_test_half": report["feature_distances"]["test"],
        "speed_against_genre": report["speed_against_genre"],
        "genre_accuracy": {
            **{
                k: v
                for k, v in report["genre_accuracy"].items()
                if k not in ("confusion", "by_half")
            },
            "test_half": {
                k: v
                for k, v in report["genre_accuracy"]["by_half"]["test"].items()
                if k != "confusion"
            },
        },  # fmt: skip
        "ten_minutes": {k: v for k, v in report["ten_minutes"].items() if k != "per_seed"},
        "generated_set": {
            "songs": len(gen),
            "tracker_f_measure": round(float(np.mean([r["f_measure"] for r in gen])), 3),
            "passing": sum(r["passes"] for r in gen),
            "stalls": sum(d["stalls"] for r in gen for d in r["dances"]),
        },
        "shared_songs": {
            "songs": len(shared),
            "bas": round(float(np.mean([r["bas"] for r in shared.values()])), 4),
            "chance": round(float(np.mean([r["chance"] for r in shared.values()])), 4),
            "stalls": sum(r["stalls"] for r in shared.values()),
            "passing_reference_beats": sum(r["passes"] for r in shared.values()),
        },
        **({"held_out_by_fold": fold_figures(report["folds"])} if "folds" in report else {}),
        "measured": report.get("measured", ""),
        "machine": report["machine"],
        "by": "python -m training.eval_dance (beat alignment: motion.beat_warp.alignment, AIST++ "
        "score vs shifted grids; foot sliding in cm/s; foot contact: EDGE's physical foot "
        "contact score; feature distances: AIST++ kinetic and geometric features of 5-s pieces, "
        "Frechet distance, test half = second half of each held-out song; genre: logistic "
        "regression on real training-song dances)",
    }
    put_evaluation(
        report["model_name"], report["model_version"], "held_out_songs", figures, models_dir
    )


def fold_figures(folds: dict) -> dict:
    """The summary of ``eval_dance``'s ``folds``: which model held out which songs, and the
    test-half figures of every fold pooled."""
    pooled = folds["pooled"]
    return {
        "folds": [{k: r[k] for k in ("fold", "model", "songs")} for r in folds["per_fold"]],
        "genre_test_half": {k: v for k, v in pooled["genre"]["test"].items() if k != "confusion"},
        "foot_sliding_cm_s": pooled["foot_sliding_cm_s"],
        "foot_contact_score": pooled["foot_contact_score"],
        "legs_jerk_m_s3_test_half": pooled["legs_jerk_m_s3"]["test"],
        "songs_on_the_beat": pooled["songs_on_the_beat"],
        "whole_songs": pooled["whole_songs"],
        "speed_against_genre": pooled["speed_against_genre"],
        "feature_distance_ratios_test_half": {
            genre: {kind: row[kind]["ratio"] for kind in ("kinetic", "geometric")}
            for genre, row in pooled["feature_distances"]["test"].items()
            if genre != "segment_seconds"
        },
    }


def record_game_invariants(report: dict, models_dir: Path) -> None:
    """``training.game_invariants``' figures into each restyling family's entry
    (``metrics.evaluation.game_invariants_held_back``): per clip, the family's worst style."""

    def worst(section: str, figure: str, family: str) -> dict:
        return {clip: v[figure][family]["worst"] for clip, v in report[section].items()}

    for family, model in report["models"].items():
        figures = {
            "loop_jump_median_steps": worst("loops", "jump_steps", family),
            "every_cycle_taken_as_a_loop": all(
                v["taken_as_loop"] for v in report["loops"].values()
            ),
            "reference_frame_moved_share_of_height": worst(
                "reference_frames", "first_frame_moved_share_of_height", family
            ),
            "every_reference_frame_found": all(
                v["found"] for v in report["reference_frames"].values()
            ),
            "in_place_travel_share_of_height": worst("in_place", "travel_share_of_height", family),
            "bandai_takes_found_with_reference_frames": len(
                report["reference_frames_found_in_bandai"]["found"]
            ),
            "measured": report.get("measured", ""),
            "by": "python -m training.game_invariants (every style; clips that chose no threshold)",
        }
        put_evaluation(
            model["name"], model["version"], "game_invariants_held_back", figures, models_dir
        )


def record(report: dict, models_dir: Path = MF.MODELS_DIR) -> None:
    """A report of any evaluation into the manifest (the foreign one by its ``half``)."""
    if "half" in report:
        record_foreign(report, models_dir)
    elif "beat_alignment" in report:
        record_dance(report, models_dir)
    elif "reference_frames_found_in_bandai" in report:
        record_game_invariants(report, models_dir)
    else:
        raise ValueError(
            "not a report of training.eval_foreign, training.eval_dance or training.game_invariants"
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("reports", nargs="+", type=Path)
    p.add_argument("--models-dir", type=Path, default=MF.MODELS_DIR)
    args = p.parse_args(argv)
    for path in args.reports:
        record(json.loads(path.read_text()), args.models_dir)
        print(f"recorded {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The foreign evaluation's report (``training.eval_foreign``) as markdown tables."""

from __future__ import annotations

from motion.styles import canonical_style
from training.foreign_measures import KEPT


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{x:.0%}"


def _real_clips(report: dict) -> tuple[dict, dict, dict[str, str]]:
    """The real clips' figures of a report, its judge's reference figures, and the words for
    them: Bandai's (leave-action-out) or a library's (its held-out takes)."""
    if "real_library" in report:
        real = report["real_library"]
        name = report["library"]["name"]
        return (
            real,
            real["held_out_takes"],
            {
                "styles": f"styles of library {name}",
                "real": f"real {name}, held-out takes",
                "recall": "real: held-out takes recall",
                "style": "style",
                "jitter": "the library's held-out takes",
            },
        )
    real = report["real_bandai"]
    return (
        real,
        real["leave_action_out"],
        {
            "styles": "merged styles",
            "real": "real Bandai, leave-action-out",
            "recall": "real: leave-action-out recall",
            "style": "style (merged)",
            "jitter": "Bandai's held-out takes",
        },
    )


def markdown(report: dict) -> str:
    """Tables of one half's report."""
    fams, unchanged = report["families"], report["unchanged"]
    real, ref, words = _real_clips(report)
    counts = ", ".join(f"{s} {n}" for s, n in report["items_by_source"].items())
    lines = [
        f"### Foreign content, {report['half']} half: {report['items']} items of "
        f"{len(report['takes'])} takes ({counts}); "
        f"{len(report['styles'])} {words['styles']}, chance {report['chance']:.1%}",
        "",
        "| | "
        + " | ".join(f"{f} ({v['model_version']})" for f, v in fams.items())
        + f" | content unchanged | {words['real']} |",
        "|---|" + "---|" * (len(fams) + 2),
    ]

    def row(label: str, per_family, unchanged_cell: str, real_cell: str) -> None:
        cells = " | ".join(per_family(v) for v in fams.values())
        lines.append(f"| {label} | {cells} | {unchanged_cell} | {real_cell} |")

    row("outputs", lambda v: str(v["n"]), str(unchanged["n"]), str(ref["n"]))
    row("top-1", lambda v: _pct(v["top1"]), "-", _pct(ref["top1"]))
    row("top-1, rig variants left out", lambda v: _pct(v["top1_originals_only"]), "-", "-")
    row(
        "top-1, mean per style",
        lambda v: _pct(v["top1_mean_per_style"]),
        "-",
        _pct(ref["top1_mean_per_style"]),
    )
    row("top-3", lambda v: _pct(v["top3"]), "-", _pct(ref["top3"]))
    row(
        "most-predicted style",
        lambda v: f"{v['most_predicted_share']:.0%} {v['most_predicted']}",
        f"{unchanged['most_predicted_share']:.0%} {unchanged['most_predicted']}",
        f"{ref['most_predicted_share']:.0%} {ref['most_predicted']}",
    )
    row(
        "styles under 30% / 10%",
        lambda v: f"{len(v['under_30'])} / {len(v['under_10'])}",
        "-",
        f"{len(ref['under_30'])} / {len(ref['under_10'])}",
    )

    def intervals(v: dict) -> str:
        return "; ".join(f"{lo:.0%}-{hi:.0%}" for lo, hi in v["intervals_90"].values())

    row("90% intervals, takes resampled: top-1; most-predicted; lowest recall", intervals, "-", "-")
    row("spread / real", lambda v: f"{v['spread_ratio']:.2f}", "-", f"1 ({real['spread']:.2f})")
    row(
        f"content kept: corr; share >= {KEPT}",
        lambda v: f"{v['content_kept']:.3f}; {v['content_kept_share']:.0%}",
        "1; 100%",
        "-",
    )
    row(
        "foot sliding (cm/s)",
        lambda v: f"{v['foot_sliding_cm_s']:.1f}",
        f"{unchanged['foot_sliding_cm_s']:.1f}",
        f"{real['foot_sliding_cm_s']:.1f} (all takes)",
    )
    for limb in ("knees", "elbows"):
        key = f"{limb}_backwards"

        def bent(a: dict, share: str = ".2%", key: str = key) -> str:
            return f"{a[key]:{share}}; {a[key + '_worst_clip']:.1%}"

        row(
            f"{limb} bent backwards: share of frames; worst clip's",
            lambda v, bent=bent: bent(v["anatomy"]),
            bent(unchanged["anatomy"]),
            bent(real["anatomy"], ".3%") + " (all takes)",
        )
    row(
        "fastest joint, body heights/s: fastest clip; 99th percentile of clips",
        lambda v: (
            f"{v['anatomy']['peak_speed_bh_s']:.1f}; {v['anatomy']['peak_speed_p99_bh_s']:.1f}"
        ),
        f"{unchanged['anatomy']['peak_speed_bh_s']:.1f}; "
        f"{unchanged['anatomy']['peak_speed_p99_bh_s']:.1f}",
        f"{real['anatomy']['peak_speed_bh_s']:.1f}; {real['anatomy']['peak_speed_p99_bh_s']:.1f}"
        " (all takes)",
    )
    row(
        f"jerk against real mocap, {words['jitter']} in their own style",
        lambda v: f"{v['held_out_jitter']['ratio']:.2f}" if v.get("held_out_jitter") else "-",
        "-",
        "1",
    )
    lines += [
        "",
        f"| {words['style']} | "
        + " | ".join(f"{f} recall" for f in fams)
        + f" | unchanged: share predicted | {words['recall']} |",
        "|---|" + "---|" * (len(fams) + 2),
    ]
    for s in report["styles"]:
        cells = " | ".join(_pct(v["recall"].get(s)) for v in fams.values())
        lines.append(
            f"| {s} | {cells} | {_pct(unchanged['predicted_share'].get(s, 0.0))} | "
            f"{_pct(ref['recall'].get(s))} |"
        )
    names = sorted({n for v in fams.values() for n in v["top1_by_name"]})
    if any(canonical_style(n) != n for n in names):
        lines += [
            "",
            "| shipped name | scored as | " + " | ".join(f"{f} top-1" for f in fams) + " |",
            "|---|---|" + "---|" * len(fams),
        ]
        for n in names:
            cells = " | ".join(_pct(v["top1_by_name"].get(n)) for v in fams.values())
            lines.append(f"| {n} | {canonical_style(n)} | {cells} |")
    sources = sorted({s for v in fams.values() for s in v["by_source"]})
    lines += [
        "",
        "| source | items | "
        + " | ".join(f"{f}: top-1, content kept, foot sliding" for f in fams)
        + " | unchanged: foot sliding |",
        "|---|---|" + "---|" * (len(fams) + 1),
    ]
    for s in sources:
        cells = " | ".join(
            f"{_pct(b['top1'])}, {b['content_kept']:.2f}, {b['foot_sliding_cm_s']:.1f}"
            if (b := v["by_source"].get(s))
            else "-"
            for v in fams.values()
        )
        lines.append(
            f"| {s} | {report['items_by_source'].get(s, 0)} | {cells} | "
            f"{unchanged['foot_sliding_by_source'].get(s, 0.0):.1f} |"
        )
    agree = ", ".join(f"{f} {_pct(v['variants_agree'])}" for f, v in fams.items())
    lines += ["", f"Rig variants said to be in the same style as their original: {agree}."]
    if "by_action_group" in ref:
        lines += [
            "",
            "Judge on real Bandai, leave-action-out: top-1 by held-out action group "
            + ", ".join(f"{g} {_pct(v)}" for g, v in ref["by_action_group"].items())
            + ".",
            "",
            "| actor group (dataset-2) | clips | right style among the group's | chance | top-1 |",
            "|---|---|---|---|---|",
        ]
        for g, v in ref["within_actor_groups"].items():
            lines.append(
                f"| {g} | {v['n']} | {_pct(v['recall_within_group'])} | {_pct(v['chance'])} | "
                f"{_pct(v['top1'])} |"
            )
    else:
        lines += [
            "",
            f"Judge trained on the {report['library']['takes']} real takes of library "
            f"{report['library']['name']} (sha256 {report['library']['sha256'][:12]}); "
            f"its reference: the {ref['n']} takes labels.csv holds out, judged by a twin "
            "trained without them.",
        ]
    lines += [
        "",
        f"Machine: {report['machine']}. Seconds: "
        + ", ".join(f"{k} {v}" for k, v in report["seconds"].items())
        + ".",
    ]
    return "\n".join(lines)

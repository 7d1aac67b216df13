"""The output smoothing an exported restyling family ships with, chosen without a judge.

    python -m model_export.output_smoothing translator|fast [--models-dir DIR]

Both families smooth their network's output rotations over time, a Gaussian of sigma
frames (``service.engines.restyling.restyled_motion``), against the frame-to-frame
jitter a network adds; the same smoothing takes the styles' own quick movements (angry's
flailing, active's pumping). So each exported model gets the smallest sigma of
:data:`CANDIDATES` at which its output, as the service finishes it, jerks no more than
real mocap with the same timing (``training.judges.held_out_jitter``: Bandai's held-out
takes restyled to their own style). The exports measure their new graphs before they write
the entry (:func:`measured`), so the entry is written once with the sigma
(``extra.output_smoothing``) and each candidate's jerk against real
(``metrics.held_out_jerk``). Run alone on an exported model (:func:`choose`), a sigma other
than its entry's is a new version.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from model_export import manifest as MF
from training.judges import engine_of, held_out_jitter, load_engine, style_names

CANDIDATES = (0.0, 0.5, 1.0, 1.5, 2.0)  # sigma, frames at 30 fps
LIMIT = 1.0  # output jerk over the real takes' jerk


def smallest_within(ratios: dict[float, float], limit: float = LIMIT) -> float:
    """The smallest sigma whose jerk ratio is at most ``limit``."""
    within = sorted(s for s, r in ratios.items() if r <= limit)
    if not within:
        worst = ", ".join(f"sigma {s:g}: {r:.2f}" for s, r in sorted(ratios.items()))
        raise ValueError(f"no output smoothing brings the jerk to {limit:g}x real ({worst})")
    return within[0]


def measure(family: str, engine, clips: list, candidates=CANDIDATES) -> dict[float, float]:
    """Each candidate sigma's held-out jerk ratio for ``engine``, loaded as the service
    loads it."""
    ratios = {}
    for sigma in candidates:
        engine.output_smoothing = sigma
        ratios[sigma] = held_out_jitter(family, engine, clips)["ratio"]
        print(f"{family}: sigma {sigma:g}, jerk {ratios[sigma]:.3f}x real", flush=True)
    return ratios


def _bandai_in(family: str, engine) -> list:
    from training.data import load_bandai

    styles = set(style_names(family, engine))
    return [c for c in load_bandai() if c.style in styles]


def measured(family: str, entry: dict, models_dir: Path) -> float:
    """The smoothing of an export's new ``entry`` (its files written, the entry not yet in
    the manifest), measured on its graphs and set in the entry: ``extra.output_smoothing``
    and ``metrics.held_out_jerk``."""
    model = MF.validated_entry(entry, models_dir)
    engine = engine_of(model, Path(models_dir))
    ratios = measure(family, engine, _bandai_in(family, engine))
    sigma = smallest_within(ratios)
    entry["extra"]["output_smoothing"] = sigma
    entry.setdefault("metrics", {})["held_out_jerk"] = {f"{s:g}": r for s, r in ratios.items()}
    print(f"{entry['name']}: output smoothing sigma {sigma:g}", flush=True)
    return sigma


def choose(family: str, models_dir: Path = MF.MODELS_DIR) -> float:
    """Measure the exported ``family`` in ``models_dir`` again and record its smoothing:
    under the entry's version when the sigma is the entry's already, else under a new one
    (the outputs change)."""
    engine, entry, models_dir = load_engine(family, Path(models_dir))
    ratios = measure(family, engine, _bandai_in(family, engine))
    sigma = smallest_within(ratios)
    same = sigma == float(entry.extra["output_smoothing"])
    MF.update_entry(
        entry.name,
        entry.version,
        extra={"output_smoothing": sigma},
        metrics={"held_out_jerk": {f"{s:g}": r for s, r in ratios.items()}},
        models_dir=models_dir,
        new_version=None if same else MF.dated_version(entry.name, models_dir),
    )
    print(f"{entry.name}: output smoothing sigma {sigma:g}", flush=True)
    return sigma


def main(argv: list[str] | None = None) -> float:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("family", choices=("translator", "fast"))
    p.add_argument("--models-dir", type=Path, default=MF.MODELS_DIR)
    args = p.parse_args(argv)
    return choose(args.family, args.models_dir)


if __name__ == "__main__":
    main()

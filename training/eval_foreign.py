"""The shipped style families judged on motion from outside Bandai, as a user would send it.

    python -m training.eval_foreign [--half dev|test|both] [--families translator fast]
        [--judge FILE | --pin-judge] [--classifier-cache DIR] [--out-dir DIR] [--limit N]
        [--library LIB --models-dir models/NAME]

writes ``foreign-<half>.json`` for each half judged (default ``runs/eval/``) and prints its
tables; ``python -m model_export.evaluations runs/eval/foreign-test.json`` records the test
half's figures in each model's manifest entry (``metrics.evaluation.foreign_test_half``).

With ``--library``: the models a studio trained on its library (``motion-style-train LIB
-o models/NAME``, in ``--models-dir``), judged by a classifier of that library's own real
takes (``foreign_judge.train_library_judge``; its reference: the takes ``labels.csv``
holds out, judged by a twin that never saw them), on the same halves of the same foreign
content; the descriptors, spread, foot sliding and anatomy are measured against the
library's takes, and the report goes to ``runs/eval/NAME/`` (``model_export.evaluations
--models-dir models/NAME`` records it). Without, everything is Bandai's, as above.

Families: the translator by style name, the fast networks, ``translator-clip``: the
translator with one real Bandai take of the requested style as the style clip
(:class:`ByStyleClip`), and ``translator-video``: with a side view of such a take as the
video's keypoints (:class:`ByStyleVideo`); the last two recorded in the translator's
manifest entry as ``foreign_test_half_style_clips`` and ``foreign_test_half_style_videos``.
The encoders trained on those takes but dataset 2's validation ones
(``training.bandai_library.held_out_take``): ``translator-clip-unseen`` and
``translator-video-unseen`` take the style only from those, for the seven styles that
have any, as a clip or a video the encoders never saw (``..._unseen_style_clips``,
``..._unseen_style_videos``).

Content (:mod:`training.foreign_content`), the judge (:mod:`training.foreign_judge`), the
measures without a classifier (:mod:`training.foreign_measures`) and the report's tables
(:mod:`training.foreign_report`) are one yardstick: figures compare across sessions only
while all of them change together.

Figures per family and half, against the merged requested style: top-1, top-3, recall per
style and per shipped name, the share of the most-predicted style, confusion counts. Spread
(no classifier): a descriptor per clip (mean and std over time of root-local joint
positions and joint speeds, standardised over real Bandai); an item's spread is the mean
pairwise distance between its outputs' descriptors for different styles (outputs of two
names of one merged style averaged first, as real takes of a style are), over the real
spread: the same between per-style mean descriptors of real Bandai takes of one action
(one dataset, one content label), averaged over actions. Content kept: hands and feet
relative to the hips in the body's facing frame, the output resampled to the content's
frame count (time warping changes it), centred 3D correlation per effector, averaged; the
mean and the share at or above 0.85. Anatomy (``foreign_measures.Limbs``): the share of
frames with a knee more than 2% of body height behind its hip-ankle line, the leg bent,
and with an elbow bent the way it cannot (``motion.anatomy.elbows_backwards``), over all
outputs and the worst output's, and the fastest joint in body heights a second, beside
the content's and real Bandai's own. Foot sliding as ``judges.skating``, beside real
Bandai mocap and the content unchanged. Jitter, for the families with networks of their
own (:func:`held_out_jitter`): their output's jerk against real mocap of the same timing,
on Bandai's held-out takes. Baseline: what the judge says of the content
unchanged. How far the recognition figures could move with other takes of the same kinds:
90% intervals with the half's takes resampled (``take_intervals``).
"""

from __future__ import annotations

import argparse
import time
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import features as Fe
from motion import kinematics as K
from motion.skeleton import Motion
from motion.styles import canonical_style
from service.engines.translator import StyleCodeJob, TransferJob
from service.metrics import StageTimer
from training.foreign_content import HALVES, Item, load_items
from training.foreign_judge import (
    PINNED_JUDGE,
    StyleJudge,
    held_out_reference,
    judge_for,
    library_judge_for,
    pin_judge,
    recognition,
    reference,
    share,
)
from training.foreign_measures import (
    KEPT,
    Limbs,
    RealBandai,
    content_kept,
    limb_figures,
    real_bandai,
    style_spread,
)
from training.foreign_report import markdown
from training.judges import (
    held_out_jitter,
    load_engine,
    skating,
    style_names,
    transfer,
)
from training.reports import publish

REPO = Path(__file__).resolve().parent.parent
STYLE_FROM = (
    "translator-clip",
    "translator-video",
    "translator-clip-unseen",
    "translator-video-unseen",
)
FAMILIES = ("translator", "fast", *STYLE_FROM)
# families measured through another's engine, and where their test half is recorded
ENGINE_OF = dict.fromkeys(STYLE_FROM, "translator")
EVALUATION_KEY = {
    "translator-clip": "foreign_test_half_style_clips",
    "translator-video": "foreign_test_half_style_videos",
    "translator-clip-unseen": "foreign_test_half_unseen_style_clips",
    "translator-video-unseen": "foreign_test_half_unseen_style_videos",
}
RESAMPLES = 2000  # bootstrap draws of a half's takes for the figures' intervals


# --------------------------------------------------------------------------- families


def _translate(engine, item: Item, style: str) -> Motion:
    """The translator as the service runs a named style: strength 1, time warp, foot clean-up."""
    return transfer("translator", engine, item.motion, style)


def _stylize(engine, item: Item, style: str) -> Motion:
    """A fast network as ``POST /v1/stylize`` runs it (foot clean-up on)."""
    return transfer("fast", engine, item.motion, style)


class ByStyleClip:
    """The translator with a real take of the style as the style clip instead of its name:
    for each item and style, one of the style's Bandai takes, picked by a hash of the item
    (its rig variants get the same) and the take, so a half's items spread over the style's
    actions and performers. Its code is the 3D encoder's (the engine's core on the take, bounded as the
    service bounds a clip's), played as the service plays a clip's (the engine's
    ``played``), and the time warp the paper's ratio of velocity factors, as ``POST
    /v1/transfer`` runs a style clip. The encoder trained on these takes (but one in ten of
    dataset 2's): a user's own clip of a style may carry it less; with ``unseen`` only
    those held-out ones are drawn, and only the styles that have any are sent
    (:meth:`sendable`). ``frames``: each take cut to its middle ``frames`` first (0: whole;
    ``training.short_style_clips``)."""

    def __init__(self, clips: list, unseen: bool = False, frames: int = 0) -> None:
        from training.bandai_library import held_out_clip
        from training.data import clip_motion

        self.frames = frames
        self.takes: dict[str, list] = {}
        for c in clips:
            if held_out_clip(c) or not unseen:
                self.takes.setdefault(canonical_style(c.style), []).append(c)
        self.motion = clip_motion
        self.codes: dict[str, object] = {}

    def sendable(self, names: list[str]) -> list[str]:
        """The shipped style names with a take to draw."""
        return [n for n in names if canonical_style(n) in self.takes]

    def take_for(self, item: Item, style: str):
        return min(
            self.takes[canonical_style(style)],
            key=lambda c: zlib.crc32(f"{item.original}|{c.name}".encode()),
        )

    def cut(self, take) -> Motion:
        """The take's motion, cut to its middle ``frames`` where that is shorter."""
        motion = self.motion(take)
        if self.frames and motion.num_frames > self.frames:
            start = (motion.num_frames - self.frames) // 2
            motion = motion.slice(start, start + self.frames)
        return motion

    def code_of(self, engine, take):
        return engine.predict(StyleCodeJob(self.cut(take)), StageTimer(engine.name))

    def __call__(self, engine, item: Item, style: str) -> Motion:
        take = self.take_for(item, style)
        if take.name not in self.codes:
            self.codes[take.name] = self.code_of(engine, take)
        code = self.codes[take.name]
        return engine.predict(TransferJob(item.motion, code), StageTimer(engine.name)).motion


class ByStyleVideo(ByStyleClip):
    """The translator with a video of the style: the take :class:`ByStyleClip` picks, seen
    from one side (yaw uniform in +-90 degrees, as training projects its views, seeded by
    the take: one video per take) as the joints OpenPose observes
    (``keypoints_of_positions``), through the service's keypoint path
    (the engine's core on the keypoints, ``played``; no velocity factor, so no time warp). Projected
    mocap is a video without a tracker's noise: real videos may carry a style less. ``frames``
    as :class:`ByStyleClip`'s, cut before the projection."""

    def code_of(self, engine, take):
        seed = zlib.crc32(f"{take.name}|view".encode())
        yaw = np.deg2rad(np.random.default_rng(seed).uniform(-90.0, 90.0))
        gpos = K.global_positions(self.cut(take))
        kp = Fe.keypoints_of_positions(gpos, yaw)
        return engine.predict(StyleCodeJob(kp), StageTimer(engine.name))


# one adapter per family: where a family's engine API changes, only its adapter does
ADAPTERS = {"translator": _translate, "fast": _stylize}


def take_intervals(
    takes: list[str], requested: list[str], predicted: list[str], resamples: int = RESAMPLES
) -> dict[str, list[float]]:
    """90% intervals (5th and 95th percentiles) of top-1, the most-predicted style's share
    and the lowest recall of a requested style, over ``resamples`` draws of the half's takes
    with replacement (seeded). A take's segments and rig variants are judged together and
    fare alike, so it is takes, not outputs, that the figures vary with."""
    rows: dict[str, list[int]] = {}
    for i, take in enumerate(takes):
        rows.setdefault(take, []).append(i)
    groups = list(rows.values())
    classes = sorted(set(requested) | set(predicted))
    asked = np.array([classes.index(r) for r in requested])
    said = np.array([classes.index(p) for p in predicted])
    hits = asked == said
    rng = np.random.default_rng(0)
    draws: dict[str, list[float]] = {"top1": [], "most_predicted_share": [], "lowest_recall": []}
    for _ in range(resamples):
        idx = np.concatenate([groups[k] for k in rng.integers(len(groups), size=len(groups))])
        draws["top1"].append(hits[idx].mean())
        draws["most_predicted_share"].append(np.bincount(said[idx]).max() / len(idx))
        n = np.bincount(asked[idx], minlength=len(classes))
        right = np.bincount(asked[idx], weights=hits[idx], minlength=len(classes))
        draws["lowest_recall"].append((right[n > 0] / n[n > 0]).min())
    return {
        k: [round(float(np.percentile(v, 5)), 4), round(float(np.percentile(v, 95)), 4)]
        for k, v in draws.items()
    }


@dataclass
class Output:
    """One item sent to one shipped style name (scored as ``style``), as the judge and the
    measures see it."""

    item: Item
    name: str
    style: str
    logp: np.ndarray
    descriptor: np.ndarray
    kept: float
    sliding: float
    limbs: Limbs


def send(
    family: str,
    engine,
    items: list[Item],
    judge: StyleJudge,
    real: RealBandai,
    log=print,
    adapter=None,
    scored_as=canonical_style,
):
    """Every item through ``family``'s shipped ``engine`` to every shipped style name
    (``adapter(engine, item, name)``, else the family's own; an adapter's
    :meth:`ByStyleClip.sendable` names only), each output scored as ``scored_as(name)``."""
    names, outputs = style_names(ENGINE_OF.get(family, family), engine), []
    if adapter is None:
        adapter = ADAPTERS[family]
    else:
        names = adapter.sendable(names)
    for i, item in enumerate(items):
        for name in names:
            out = adapter(engine, item, name)
            outputs.append(
                Output(
                    item,
                    name,
                    scored_as(name),
                    judge.log_probabilities(out),
                    real.standardised(out),
                    content_kept(out, item.motion),
                    skating(out),
                    Limbs.of(out),
                )
            )
        if (i + 1) % 10 == 0 or i + 1 == len(items):
            log(f"[{family}] {i + 1}/{len(items)} items")
    return outputs


def family_figures(outputs: list[Output], classes: list[str], real: RealBandai) -> dict:
    """The figures of one family's ``outputs`` (see the module docstring), and by source:
    top-1, content kept and foot sliding; a rig variant's outputs also against its
    original's (``variants_agree``: the same style said for the same name)."""
    figures = recognition([o.style for o in outputs], np.array([o.logp for o in outputs]), classes)
    predicted = figures.pop("predicted")
    hits = [p == o.style for o, p in zip(outputs, predicted, strict=True)]
    by_name: dict[str, list[bool]] = {}
    by_source: dict[str, list[int]] = {}
    for i, o in enumerate(outputs):
        by_name.setdefault(o.name, []).append(hits[i])
        by_source.setdefault(o.item.source, []).append(i)
    figures["top1_by_name"] = {n: share(v) for n, v in sorted(by_name.items())}
    figures["intervals_90"] = take_intervals(
        [o.item.take for o in outputs], [o.style for o in outputs], predicted
    )
    figures["by_source"] = {
        source: {
            "n": len(rows),
            "top1": share([hits[i] for i in rows]),
            "content_kept": round(float(np.mean([outputs[i].kept for i in rows])), 4),
            "foot_sliding_cm_s": round(float(np.mean([outputs[i].sliding for i in rows])), 2),
        }
        for source, rows in sorted(by_source.items())
    }
    said = {(o.item.name, o.name): p for o, p in zip(outputs, predicted, strict=True)}
    variants = [i for i, o in enumerate(outputs) if o.item.name != o.item.original]
    originals = set(range(len(outputs))) - set(variants)
    figures["top1_originals_only"] = share([hits[i] for i in sorted(originals)])
    figures["variants_agree"] = share(
        [said.get((outputs[i].item.original, outputs[i].name)) == predicted[i] for i in variants]
    )
    per_item: dict[str, list[Output]] = {}
    for o in outputs:
        per_item.setdefault(o.item.name, []).append(o)
    spread = float(
        np.mean(
            [
                style_spread(np.array([o.descriptor for o in os]), [o.style for o in os])
                for os in per_item.values()
            ]
        )
    )
    kept = [o.kept for o in outputs]
    figures.update(
        spread=round(spread, 4),
        spread_ratio=round(spread / real.spread, 4),
        content_kept=round(float(np.mean(kept)), 4),
        content_kept_share=share([k >= KEPT for k in kept]),
        foot_sliding_cm_s=round(float(np.mean([o.sliding for o in outputs])), 2),
        anatomy=limb_figures([o.limbs for o in outputs]),
        outputs=[
            [o.item.name, o.name, p, round(o.kept, 3)]
            for o, p in zip(outputs, predicted, strict=True)
        ],
    )
    return figures


def unchanged_figures(items: list[Item], judge: StyleJudge) -> dict:
    """What the judge says of the content itself, and its foot sliding (also by source)."""
    said = Counter(judge.classes[int(np.argmax(judge.log_probabilities(i.motion)))] for i in items)
    most, count = said.most_common(1)[0]
    sliding = {i.name: skating(i.motion) for i in items}
    by_source: dict[str, list[float]] = {}
    for i in items:
        by_source.setdefault(i.source, []).append(sliding[i.name])
    return {
        "n": len(items),
        "predicted_share": {s: round(k / len(items), 4) for s, k in said.most_common()},
        "most_predicted": most,
        "most_predicted_share": round(count / len(items), 4),
        "foot_sliding_cm_s": round(float(np.mean(list(sliding.values()))), 2),
        "foot_sliding_by_source": {
            s: round(float(np.mean(v)), 2) for s, v in sorted(by_source.items())
        },
        "anatomy": limb_figures([Limbs.of(i.motion) for i in items]),
    }


# --------------------------------------------------------------------------- evaluation


def _listed(names: list[str]) -> str:
    return ", ".join(sorted(names))


def evaluate(
    halves: tuple[str, ...],
    families: tuple[str, ...] = FAMILIES,
    classifier_cache: Path | None = None,
    limit: int | None = None,
    log=print,
    pinned: Path | None = None,
    pin: bool = False,
    library: Path | None = None,
    models_dir: Path | None = None,
    style_clip_frames: int = 0,
) -> dict[str, dict]:
    """The report of each of ``halves`` (see the module docstring); ``limit``: only the first
    N items of each half (a smoke run); ``style_clip_frames``: the style clips' and videos'
    length (:class:`ByStyleClip`'s ``frames``). The judge is the ``pinned`` file where it exists,
    else trained (and kept in ``classifier_cache``); ``pin`` writes it to
    :data:`PINNED_JUDGE`. With ``library``: the models in ``models_dir`` judged against
    that library's real takes (:func:`training.foreign_judge.train_library_judge`)."""
    from training.measuring_machine import measuring_machine

    started = time.time()
    if library is None:
        from training.data import load_bandai

        clips, scored_as = load_bandai(), canonical_style
    else:
        from training import library as L

        clips, scored_as = L.read_library(library), str
    # the judge's classes, before it trains: a model it could not score stops the run here
    real_styles = {scored_as(c.style) for c in clips}
    loaded = {e: load_engine(e, models_dir) for e in {ENGINE_OF.get(f, f) for f in families}}
    for e, (engine, entry, _) in loaded.items():
        unjudged = {scored_as(n) for n in style_names(e, engine)} - real_styles
        if unjudged:
            raise ValueError(
                f"{entry.name} serves style(s) {_listed(unjudged)} that the judge's real "
                f"takes lack (they have {_listed(real_styles)})"
            )
    engines = {f: loaded[ENGINE_OF.get(f, f)] for f in families}
    seconds = {"clips and engines": round(time.time() - started, 1)}
    t = time.time()
    if library is None:
        judge = judge_for(clips, classifier_cache, pinned)
        if pin:
            pin_judge(judge, clips)
        source = pinned if pinned is not None and pinned.exists() else "trained"
    else:
        judge = library_judge_for(clips, classifier_cache)
        source = f"trained on library {Path(library).resolve().name}"
    seconds["judge"] = round(time.time() - t, 1)
    log(f"judge ready ({source}, {seconds['judge']} s)")
    t = time.time()
    real = real_bandai(clips)
    ref = reference(judge) if library is None else held_out_reference(judge)
    items = {h: v[:limit] if limit else v for h, v in load_items(halves).items()}
    seconds["references and items"] = round(time.time() - t, 1)
    adapters = {
        "translator-clip": ByStyleClip(clips, frames=style_clip_frames),
        "translator-video": ByStyleVideo(clips, frames=style_clip_frames),
        "translator-clip-unseen": ByStyleClip(clips, unseen=True, frames=style_clip_frames),
        "translator-video-unseen": ByStyleVideo(clips, unseen=True, frames=style_clip_frames),
    }
    outputs: dict[str, list[Output]] = {}
    jitter: dict[str, dict] = {}
    for f in families:
        t = time.time()
        everything = [i for h in halves for i in items[h]]
        outputs[f] = send(
            f, engines[f][0], everything, judge, real, log, adapters.get(f), scored_as
        )
        if f in ADAPTERS:  # the families with networks of their own
            jitter[f] = held_out_jitter(f, engines[f][0], clips)
        seconds[f"{f} transfers and judging"] = round(time.time() - t, 1)
    real_figures = {
        "spread": round(real.spread, 4),
        "spread_by_dataset": real.spread_by_dataset,
        "foot_sliding_cm_s": round(real.sliding, 2),
        "anatomy": real.anatomy,
    }
    if library is None:
        real_section = {"real_bandai": {"leave_action_out": ref, **real_figures}}
    else:
        from training import library as L

        lib, _ = L.read_labels(library)
        real_section = {
            "library": {"name": lib.name, "sha256": lib.content_hash(), "takes": len(clips)},
            "real_library": {"held_out_takes": ref, **real_figures},
        }
    reports = {}
    for h in halves:
        takes = sorted({i.take for i in items[h]})
        reports[h] = {
            "half": h,
            "items": len(items[h]),
            "takes": takes,
            "items_by_source": dict(Counter(i.source for i in items[h])),
            "styles": judge.classes,
            "chance": round(1 / len(judge.classes), 4),
            "families": {
                f: {
                    "model_name": engines[f][1].name,
                    "model_version": engines[f][1].version,
                    "names_sent": sorted({o.name for o in outputs[f]}),
                    "held_out_jitter": jitter.get(f),
                    **family_figures(
                        [o for o in outputs[f] if o.item.take in takes], judge.classes, real
                    ),
                }
                for f in families
            },
            "unchanged": unchanged_figures(items[h], judge),
            **real_section,
            "machine": measuring_machine(),
            "measured": time.strftime("%Y-%m-%d"),
            "seconds": {**seconds, "total": round(time.time() - started, 1)},
        }
    return reports


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--half", choices=(*HALVES, "both"), default="dev")
    p.add_argument("--families", nargs="+", choices=FAMILIES, default=list(FAMILIES))
    p.add_argument(
        "--classifier-cache",
        type=Path,
        default=REPO / "runs/eval/classifiers",
        help="keep the trained judge here (keyed by its code and the takes)",
    )
    p.add_argument(
        "--out-dir",
        type=Path,
        help="writes foreign-<half>.json here (default runs/eval, with --library runs/eval/NAME)",
    )
    p.add_argument(
        "--judge",
        type=Path,
        default=PINNED_JUDGE,
        help="the pinned judge (default the committed one); trained when the file is missing",
    )
    p.add_argument(
        "--pin-judge",
        action="store_true",
        help="train a judge (or take the cached one) and write it to the committed file",
    )
    p.add_argument("--limit", type=int, default=None, help="only the first N items of each half")
    p.add_argument(
        "--library",
        type=Path,
        help="judge by a classifier of this library's real takes (training.library)",
    )
    p.add_argument(
        "--models-dir",
        type=Path,
        help="the models folder to judge (with --library, required: the one trained on it)",
    )
    args = p.parse_args(argv)
    if args.library is not None:
        if args.models_dir is None:
            p.error("--library needs --models-dir: the models folder trained on it")
        if args.pin_judge:
            p.error("--pin-judge pins Bandai's judge; a library's judge is trained from it")
    halves = HALVES if args.half == "both" else (args.half,)
    reports = evaluate(
        halves,
        tuple(args.families),
        args.classifier_cache,
        args.limit,
        pinned=None if args.pin_judge else args.judge,
        pin=args.pin_judge,
        library=args.library,
        models_dir=args.models_dir,
    )
    out_dir = args.out_dir or REPO / "runs/eval"
    if args.out_dir is None and args.library is not None:
        out_dir = out_dir / args.models_dir.resolve().name
    for h, report in reports.items():
        publish(report, markdown(report), out_dir / f"foreign-{h}.json")
    return 0


if __name__ == "__main__":
    # as the imported module, so the pickled judge names ``training.eval_foreign`` classes
    from training import eval_foreign

    raise SystemExit(eval_foreign.main())

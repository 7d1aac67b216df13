"""The shipped style families judged on motion from outside Bandai, as a user would send it.

    python -m training.eval_foreign [--half dev|test|both] [--families translator fast]
        [--judge FILE | --pin-judge] [--classifier-cache DIR] [--out-dir DIR] [--limit N]

writes ``foreign-<half>.json`` for each half judged (default ``runs/eval/``) and prints its
tables; ``python -m model_export.evaluations runs/eval/foreign-test.json`` records the test
half's figures in each model's manifest entry (``metrics.evaluation.foreign_test_half``).

Content: the shared CMU 31-joint takes, Xia's clips and the CMU dance takes (43-joint and
3ds Max layouts; 05_20, in both CMU folders, once), canonical at 30 fps through
``training.data``'s loaders. cgspeed's synthetic T-pose first frame, which those loaders keep
for ``cmu-31``, is dropped (the body jumps 55-256 cm into it). Clips longer than 8 s are cut
into equal segments of at most 8 s; beyond four segments, four evenly spaced 8 s windows.
A few CMU-31 and Xia takes come again as other rigs send them: Mixamo names (``ZXY``
channels), and Unreal names with an extra root, Z up and in metres; each is written as BVH
text and read back through the service's own path (``service.clips.load_clip``).
They land within 0.001 cm of the original on the canonical skeleton, so they check the rig
path (``variants_agree``) and weigh their takes three times in the headline figures
(``top1_originals_only`` leaves them out; ``by_source`` shows each source apart).

Halves: by source take (a take's segments and variants stay together). Within each source
folder takes are ordered by a hash of their name and dealt alternately to dev and test,
the alternation running on across folders so that odd counts balance; variants are made of
the first two CMU-31 and two Xia takes of each half in that order. The report says its
half; nothing here reads the test half to choose anything.

Style judge: the convolutional window classifier of ``training.judges``
(``ConvClipClassifier``, three seeds, one thread) on every real Bandai take and its mirror
image, with the 16 merged style names (``motion.styles``); a clip's distribution is its
windows' mean log-probability, so top-3 is read from it. It reads heights over each clip's
own floor (``judges.frame_features``): where a content's floor lies, which the foot
clean-up keeps, is not a style. Its reference ("real clips") is
leave-action-out: five folds by action group (walks, runs, waves, raises, the rest), each
judged by networks that never saw that group. The judge every evaluation uses is the
committed ``training/foreign_judge.pt`` (``--pin-judge`` replaces it): trained again, on
another machine or after an edit to the code it reads motion through, it comes out
different, and the same outputs score 3-4 points apart. It carries what it said of a few
real takes and refuses to judge if it now says otherwise (the features changed). Without
it, trained classifiers and the reference are cached by a hash of the code and the takes.

Style or actor: in Bandai dataset-2 each style is one actor, three actors sharing seven
styles. Every clip is retargeted onto one canonical skeleton (bone lengths averaged over
the data) before features are taken, so body proportions, the plainest trace of an
actor, never reach the judge; what may remain is the actor's manner. The within-actor
figures measure it: over held-out dataset-2 clips of a group of styles one actor
performed, how often the judge, restricted to that group's styles, names the right one. A
judge that read the actor would be at chance there.

Families: the translator by style name, the fast networks, ``translator-clip``: the
translator with one real Bandai take of the requested style as the style clip
(:class:`ByStyleClip`), and ``translator-video``: with a side view of such a take as the
video's keypoints (:class:`ByStyleVideo`); the last two recorded in the translator's
manifest entry as ``foreign_test_half_style_clips`` and ``foreign_test_half_style_videos``.
The encoders trained on those takes but dataset 2's validation ones
(``training.translator.fit.held_out_take``): ``translator-clip-unseen`` and
``translator-video-unseen`` take the style only from those, for the seven styles that
have any, as a clip or a video the encoders never saw (``..._unseen_style_clips``,
``..._unseen_style_videos``).

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
mean and the share at or above 0.85. Foot sliding as ``judges.skating``, beside real
Bandai mocap and the content unchanged. Jitter, for the families with networks of their
own (:func:`held_out_jitter`): their output's jerk against real mocap of the same timing,
on Bandai's held-out takes. Baseline: what the judge says of the content
unchanged. How far the recognition figures could move with other takes of the same kinds:
90% intervals with the half's takes resampled (``take_intervals``).

Over 600 lines in one module: the split, the judge, the measures and the report are
one yardstick; figures compare across sessions only while all of them change together.
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import inspect
import json
import pickle
import time
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import canonical as C
from motion import features as Fe
from motion import kinematics as K
from motion import rotations as rot
from motion.skeleton import Motion
from motion.styles import canonical_style
from service.engines.translator import StyleCodeJob, TransferJob
from service.metrics import StageTimer
from training import judges
from training.judges import (
    ConvClipClassifier,
    frame_features,
    held_out_jitter,
    load_engine,
    segments,
    skating,
    style_names,
    transfer,
)

REPO = Path(__file__).resolve().parent.parent
FOLDERS = ("cmu-31", "xia", "cmu-dance-43", "cmu-dance-3dsmax")
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
HALVES = ("dev", "test")
VARIANT_FOLDERS, VARIANT_TAKES = ("cmu-31", "xia"), 2  # takes per folder and half
T_POSE_FIRST = ("cmu-31",)  # folders whose files open with cgspeed's synthetic T-pose frame
EFFECTORS = [C.INDEX[n] for n in ("Hand_L", "Hand_R", "Foot_L", "Foot_R")]
KEPT = 0.85  # content-kept correlation counted as kept
PINNED_JUDGE = REPO / "training" / "foreign_judge.pt"  # the yardstick, committed
CHECK_TAKES = 6  # real takes a pinned judge re-judges when loaded
RESAMPLES = 2000  # bootstrap draws of a half's takes for the figures' intervals
ACTOR_GROUPS = (
    ("active", "elderly", "exhausted"),
    ("feminine", "youthful"),
    ("masculine", "normal"),
)


# --------------------------------------------------------------------------- content


@dataclass(frozen=True)
class Item:
    """One foreign clip sent to every style: ``take`` ("folder/stem") decides its half,
    ``source`` is its folder or ``folder@variant``."""

    name: str
    take: str
    source: str
    motion: Motion

    @property
    def original(self) -> str:
        """The name of the item a rig variant repeats (its own name otherwise)."""
        return self.name.split("@", 1)[0]


def foreign_takes(root: Path) -> dict[str, list[str]]:
    """The source takes of each folder of :data:`FOLDERS` under ``root`` ("folder/stem"),
    a take in two folders (CMU 05_20) only in the first."""
    seen, takes = set(), {}
    for folder in FOLDERS:
        stems = [p.stem for p in sorted((root / folder).glob("*.bvh")) if p.stem not in seen]
        seen.update(stems)
        takes[folder] = [f"{folder}/{s}" for s in stems]
    return takes


def _take_order(take: str) -> str:
    return hashlib.sha256(take.encode()).hexdigest()


def split_halves(takes: dict[str, list[str]]) -> dict[str, str]:
    """Each take's half: within a folder (folders in sorted order) takes ordered by a hash
    of their name are dealt to dev and test in turn, the turn carrying over between folders."""
    half_of, turn = {}, 0
    for folder in sorted(takes):
        for take in sorted(takes[folder], key=_take_order):
            half_of[take] = HALVES[turn % 2]
            turn += 1
    return half_of


def rig_variants(motion: Motion) -> dict[str, Motion]:
    """A CMU 31-joint ``motion`` as other tools export it: Mixamo names and ``ZXY``
    channels; Unreal names, an extra root, Z up and in metres."""
    from training import rig_variants as RV

    mixamo = RV.with_channels(RV.renamed(motion, RV.CMU_TO_MIXAMO), "ZXY")
    unreal = RV.renamed(motion, RV.CMU_TO_UNREAL)
    unreal = RV.with_extra_root(RV.scaled(RV.z_up(unreal), 0.01))
    return {"mixamo": mixamo, "unreal-z-up-m": unreal}


def through_service(motion: Motion) -> Motion:
    """``motion`` written as BVH text and read onto the canonical skeleton as a request is."""
    from motion import bvh
    from service.clips import Upload, load_clip
    from service.config import Settings

    upload = Upload("content", data=bvh.dumps(motion).encode())
    return load_clip(upload, Settings(), StageTimer("eval-foreign")).canonical


def load_items(halves: tuple[str, ...], root: Path | None = None) -> dict[str, list[Item]]:
    """The items of each of ``halves``: every take's segments, and its rig variants' where
    it is among the first :data:`VARIANT_TAKES` of its folder and half."""
    from motion import bvh
    from training.data import data_dir, load_bvh_folder, load_cmu_dance

    root = root or data_dir()
    takes = foreign_takes(root)
    half_of = split_halves(takes)
    clips = {f"{f}/{c.take}": c for f in ("cmu-31", "xia") for c in load_bvh_folder(f, root)}
    dance = {c.take: c for c in load_cmu_dance(root)}
    out: dict[str, list[Item]] = {h: [] for h in halves}
    for folder, names in takes.items():
        chosen = {h: sorted((t for t in names if half_of[t] == h), key=_take_order) for h in HALVES}
        for take in names:
            half = half_of[take]
            if half not in out:
                continue
            stem = take.split("/", 1)[1]
            clip = clips[take] if take in clips else dance[stem]
            skip = 1 if folder in T_POSE_FIRST else 0
            versions = {folder: clip.motion.slice(skip)}
            if folder in VARIANT_FOLDERS and take in chosen[half][:VARIANT_TAKES]:
                raw = bvh.load(root / folder / f"{stem}.bvh")
                for name, variant in rig_variants(raw).items():
                    versions[f"{folder}@{name}"] = through_service(variant).slice(skip)
            for source, motion in versions.items():
                parts = segments(motion)
                for k, part in enumerate(parts):
                    label = take + (f"#{k + 1}" if len(parts) > 1 else "")
                    label += source[len(folder) :]
                    out[half].append(Item(label, take, source, part))
    return out


# --------------------------------------------------------------------------- measures


def effector_paths(motion: Motion) -> np.ndarray:
    """``(F, 4, 3)`` hands and feet relative to the hips, in the body's facing frame."""
    gpos = K.global_positions(motion)
    relative = gpos[:, EFFECTORS] - gpos[:, [Fe.HIPS]]
    return rot.apply(rot.inv(Fe.facing(gpos))[:, None], relative)


def path_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Centred 3D correlation of paths ``a`` and ``b`` ``(F, E, 3)`` per effector,
    ``sum(a.b) / sqrt(sum|a|^2 sum|b|^2)`` over frames with means removed; mean over ``E``."""
    a, b = a - a.mean(axis=0), b - b.mean(axis=0)
    num = (a * b).sum(axis=(0, 2))
    den = np.sqrt((a * a).sum(axis=(0, 2)) * (b * b).sum(axis=(0, 2)))
    return float(np.mean(num / np.maximum(den, 1e-12)))


def resampled(motion: Motion, frames: int) -> Motion:
    """``motion`` stretched evenly onto ``frames`` frames (undoes a uniform time warp)."""
    return K.resample_at(motion, np.linspace(0.0, motion.num_frames - 1, frames), motion.fps)


def content_kept(output: Motion, content: Motion) -> float:
    """:func:`path_correlation` of ``output``'s hands and feet with ``content``'s, the
    output resampled to the content's frame count."""
    out = resampled(output, content.num_frames)
    return path_correlation(effector_paths(out), effector_paths(content))


def descriptor(motion: Motion) -> np.ndarray:
    """``(2 * 84,)`` mean and std over time of root-local body joint positions (leg lengths)
    and joint speeds: what the spread compares, no classifier involved."""
    enc = Fe.encode(motion)
    pos = enc.style3d.reshape(len(enc.style3d), -1, 3).astype(np.float64)
    speed = np.linalg.norm(K.velocities(pos, motion.fps), axis=-1)
    per_frame = np.concatenate([pos.reshape(len(pos), -1), speed], axis=1)
    return np.concatenate([per_frame.mean(axis=0), per_frame.std(axis=0)])


def mean_pairwise_distance(x: np.ndarray) -> float:
    """Mean Euclidean distance over the pairs of rows of ``x (N, D)``; 0 for ``N < 2``."""
    from scipy.spatial.distance import pdist

    return float(pdist(x).mean()) if len(x) > 1 else 0.0


def style_spread(descriptors: np.ndarray, styles: list[str]) -> float:
    """Mean pairwise distance between the mean descriptors of each style."""
    names = sorted(set(styles))
    means = [descriptors[[s == n for s in styles]].mean(axis=0) for n in names]
    return mean_pairwise_distance(np.array(means))


# --------------------------------------------------------------------------- the judge


def action_group(content: str) -> str:
    """The fold a Bandai action is held out in: walks (turns, back, sideways), runs (and
    dashes), waves (and byes), raises, or other."""
    if content.startswith("walk"):
        return "walks"
    if content in ("run", "dash"):
        return "runs"
    if content.startswith("wave") or content in ("bye", "byebye"):
        return "waves"
    if content.startswith("raise"):
        return "raises"
    return "other"


@dataclass
class StyleJudge:
    """The classifier of every real Bandai take (and mirror), and what its leave-action-out
    twins made of each held-out take (``held_out``: take, dataset, content, style, group,
    log-probabilities over :attr:`classes`)."""

    classifier: ConvClipClassifier
    held_out: list[dict]

    @property
    def classes(self) -> list[str]:
        return self.classifier.classes

    def log_probabilities(self, motion: Motion) -> np.ndarray:
        return self.classifier.log_probabilities(frame_features(motion))


def train_judge(clips: list) -> StyleJudge:
    """:class:`StyleJudge` of real Bandai ``clips`` (merged style labels, mirrors added)."""
    feats = [frame_features(c.motion) for c in clips]
    mirrors = [frame_features(C.mirrored(c.motion)) for c in clips]
    labels = [canonical_style(c.style) for c in clips]
    groups = [action_group(c.content) for c in clips]
    judge = StyleJudge(ConvClipClassifier(feats + mirrors, labels + labels), [])
    for group in sorted(set(groups)):
        keep = [i for i, g in enumerate(groups) if g != group]
        kept_labels = [labels[i] for i in keep]
        fold = ConvClipClassifier(
            [feats[i] for i in keep] + [mirrors[i] for i in keep], kept_labels + kept_labels
        )
        if fold.classes != judge.classes:
            raise ValueError(
                f"holding out {group} leaves styles {set(judge.classes) - set(fold.classes)} unseen"
            )
        for i in (i for i, g in enumerate(groups) if g == group):
            c = clips[i]
            judge.held_out.append(
                {
                    "take": c.take,
                    "dataset": c.dataset,
                    "content": c.content,
                    "style": labels[i],
                    "group": group,
                    "logp": fold.log_probabilities(feats[i]),
                }
            )
    return judge


def motion_sources(*modules: str) -> list[Path]:
    """The files of ``motion`` modules ``modules`` and of every ``motion`` module they import,
    found by reading their imports."""
    seen, todo = set(), list(modules)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for node in ast.walk(ast.parse((REPO / "motion" / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "motion":
                todo += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("motion."):
                todo.append(node.module.split(".")[1])
            elif isinstance(node, ast.Import):
                todo += [a.name.split(".")[1] for a in node.names if a.name.startswith("motion.")]
    return sorted(REPO / "motion" / f"{name}.py" for name in seen)


def judge_key(clips: list) -> str:
    """What a trained judge depends on: the code that makes it (this module's, the features
    and the classifier of ``training.judges``, and the ``motion`` modules they read motion
    through) and the takes (labels and the canonical motion itself: ``training.data``'s clip
    cache does not notice when retargeting changes). Other edits keep a cached judge."""
    key = hashlib.sha256()
    for part in (frame_features, ConvClipClassifier, train_judge, action_group, StyleJudge):
        key.update(inspect.getsource(part).encode())
    key.update(repr((judges.WINDOW, judges.HOP, judges._MIRROR, judges._BODY_MIRROR)).encode())
    for path in motion_sources("features", "canonical", "styles"):
        key.update(path.read_bytes())
    for c in sorted(clips, key=lambda c: c.take):
        key.update(json.dumps([c.take, c.style, c.content]).encode())
        key.update(np.ascontiguousarray(c.lrot).tobytes() + np.ascontiguousarray(c.root).tobytes())
    return key.hexdigest()


def judge_for(clips: list, cache: Path | None, pinned: Path | None = None) -> StyleJudge:
    """The ``pinned`` judge where that file exists (:func:`pinned_judge`), else
    :func:`train_judge`, kept in ``cache`` under :func:`judge_key`."""
    if pinned is not None and pinned.exists():
        return pinned_judge(pinned, clips)
    if cache is None:
        return train_judge(clips)
    path = Path(cache) / f"foreign-judge-{judge_key(clips)[:16]}.pkl"
    if path.exists():
        with path.open("rb") as f:
            return pickle.load(f)
    judge = train_judge(clips)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    with partial.open("wb") as f:
        pickle.dump(judge, f)
    partial.replace(path)
    return judge


def pin_judge(judge: StyleJudge, clips: list, path: Path = PINNED_JUDGE) -> None:
    """Write ``judge`` as the yardstick later evaluations use (:func:`pinned_judge`), with
    what it says of the first :data:`CHECK_TAKES` real takes. A judge trained again on
    another machine, or after any edit to the code it is keyed on, comes out different
    (3-4 points of top-1 on the same outputs), so figures only compare under one file."""
    import torch

    check = sorted(clips, key=lambda c: c.take)[:CHECK_TAKES]
    state = {
        "classifier": judge.classifier.state(),
        "held_out": [{**h, "logp": torch.from_numpy(h["logp"])} for h in judge.held_out],
        "trained_under": judge_key(clips),
        "check": {c.take: torch.from_numpy(judge.log_probabilities(c.motion)) for c in check},
    }
    torch.save(state, path)


def pinned_judge(path: Path, clips: list) -> StyleJudge:
    """The judge :func:`pin_judge` wrote, once it judges its check takes among ``clips`` as
    it did then: otherwise the features it reads have changed, and it refuses."""
    import torch

    state = torch.load(path, weights_only=True)
    judge = StyleJudge(
        ConvClipClassifier.from_state(state["classifier"]),
        [{**h, "logp": h["logp"].numpy()} for h in state["held_out"]],
    )
    by_take = {c.take: c for c in clips}
    for take, said in state["check"].items():
        now = judge.log_probabilities(by_take[take].motion) if take in by_take else None
        if now is None or not np.allclose(now, said.numpy(), atol=1e-4):
            raise ValueError(
                f"{path} judges take {take} differently now: the features it reads changed; "
                "train a new judge and pin it (python -m training.eval_foreign --pin-judge)"
            )
    return judge


# --------------------------------------------------------------------------- figures


def _share(xs) -> float | None:
    return round(float(np.mean(xs)), 4) if len(xs) else None


def recognition(requested: list[str], logp: np.ndarray, classes: list[str]) -> dict:
    """Top-1, top-3, recall per requested style (and its mean), what is predicted and how
    often, and confusion counts (requested -> predicted), of clips asked to be in
    ``requested`` with log-probabilities ``logp (N, len(classes))``."""
    order = np.argsort(-logp, axis=1, kind="stable")
    predicted = [classes[i] for i in order[:, 0]]
    top3 = [r in {classes[i] for i in row[:3]} for r, row in zip(requested, order, strict=True)]
    hits = [p == r for p, r in zip(predicted, requested, strict=True)]
    recall = {
        s: _share([h for h, r in zip(hits, requested, strict=True) if r == s])
        for s in sorted(set(requested))
    }
    counts = Counter(predicted)
    most, most_n = counts.most_common(1)[0] if counts else (None, 0)
    confusion: dict[str, dict[str, int]] = {}
    for r, p in zip(requested, predicted, strict=True):
        confusion.setdefault(r, Counter())[p] += 1
    return {
        "n": len(requested),
        "top1": _share(hits),
        "top3": _share(top3),
        "top1_mean_per_style": _share(list(recall.values())),
        "recall": recall,
        "under_30": sorted(s for s, r in recall.items() if r < 0.3),
        "under_10": sorted(s for s, r in recall.items() if r < 0.1),
        "most_predicted": most,
        "most_predicted_share": round(most_n / max(len(predicted), 1), 4),
        "predicted_share": {s: round(k / len(predicted), 4) for s, k in counts.most_common()},
        "confusion": {r: dict(c.most_common()) for r, c in confusion.items()},
        "predicted": predicted,
    }


def within_actor(held_out: list[dict], classes: list[str]) -> dict:
    """Per :data:`ACTOR_GROUPS` group, over held-out dataset-2 clips of its styles (one
    actor's): how often the right style is named among the group's styles only, against
    chance, and the unrestricted top-1."""
    out = {}
    for group in ACTOR_GROUPS:
        rows = [h for h in held_out if h["style"] in group and h["dataset"] == "dataset-2"]
        columns = [classes.index(s) for s in group]
        named = [group[int(np.argmax(h["logp"][columns]))] for h in rows]
        top1 = [classes[int(np.argmax(h["logp"]))] == h["style"] for h in rows]
        out[", ".join(group)] = {
            "n": len(rows),
            "recall_within_group": _share(
                [n == h["style"] for n, h in zip(named, rows, strict=True)]
            ),
            "chance": round(1 / len(group), 4),
            "top1": _share(top1),
        }
    return out


def reference(judge: StyleJudge) -> dict:
    """The judge's leave-action-out figures on real Bandai takes ("real clips")."""
    held = judge.held_out
    figures = recognition(
        [h["style"] for h in held], np.array([h["logp"] for h in held]), judge.classes
    )
    figures.pop("predicted")
    figures.pop("confusion")
    figures["by_action_group"] = {
        g: _share(
            [
                judge.classes[int(np.argmax(h["logp"]))] == h["style"]
                for h in held
                if h["group"] == g
            ]
        )
        for g in sorted({h["group"] for h in held})
    }
    figures["within_actor_groups"] = within_actor(held, judge.classes)
    return figures


@dataclass
class RealBandai:
    """What the spread and the foot sliding compare with: the descriptors' standardisation,
    the real spread (overall and per dataset) and real mocap's foot sliding."""

    mean: np.ndarray
    std: np.ndarray
    spread: float
    spread_by_dataset: dict[str, float]
    sliding: float

    def standardised(self, motion: Motion) -> np.ndarray:
        return (descriptor(motion) - self.mean) / self.std


def real_bandai(clips: list) -> RealBandai:
    raw = np.array([descriptor(c.motion) for c in clips])
    mean, std = raw.mean(axis=0), raw.std(axis=0) + 1e-6
    x = (raw - mean) / std
    actions: dict[tuple[str, str], list[int]] = {}
    for i, c in enumerate(clips):
        actions.setdefault((c.dataset, c.content), []).append(i)
    spreads: dict[str, list[float]] = {}
    for (dataset, _), rows in sorted(actions.items()):
        styles = [canonical_style(clips[i].style) for i in rows]
        if len(set(styles)) > 1:
            spreads.setdefault(dataset, []).append(style_spread(x[rows], styles))
    every = [s for v in spreads.values() for s in v]
    return RealBandai(
        mean,
        std,
        float(np.mean(every)),
        {d: round(float(np.mean(v)), 4) for d, v in spreads.items()},
        float(np.mean([skating(c.motion) for c in clips])),
    )


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
    (:meth:`sendable`)."""

    def __init__(self, clips: list, unseen: bool = False) -> None:
        from training.data import clip_motion
        from training.translator.fit import held_out_take

        self.takes: dict[str, list] = {}
        for c in clips:
            if held_out_take(c.name) or not unseen:
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

    def code_of(self, engine, take):
        return engine.predict(StyleCodeJob(self.motion(take)), StageTimer(engine.name))

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
    mocap is a video without a tracker's noise: real videos may carry a style less."""

    def code_of(self, engine, take):
        seed = zlib.crc32(f"{take.name}|view".encode())
        yaw = np.deg2rad(np.random.default_rng(seed).uniform(-90.0, 90.0))
        gpos = K.global_positions(self.motion(take))
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
    """One item sent to one shipped style name, as the judge and the measures see it."""

    item: Item
    name: str
    logp: np.ndarray
    descriptor: np.ndarray
    kept: float
    sliding: float

    @property
    def style(self) -> str:
        return canonical_style(self.name)


def send(
    family: str,
    engine,
    items: list[Item],
    judge: StyleJudge,
    real: RealBandai,
    log=print,
    adapter=None,
):
    """Every item through ``family``'s shipped ``engine`` to every shipped style name
    (``adapter(engine, item, name)``, else the family's own; an adapter's
    :meth:`ByStyleClip.sendable` names only)."""
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
                    judge.log_probabilities(out),
                    real.standardised(out),
                    content_kept(out, item.motion),
                    skating(out),
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
    figures["top1_by_name"] = {n: _share(v) for n, v in sorted(by_name.items())}
    figures["intervals_90"] = take_intervals(
        [o.item.take for o in outputs], [o.style for o in outputs], predicted
    )
    figures["by_source"] = {
        source: {
            "n": len(rows),
            "top1": _share([hits[i] for i in rows]),
            "content_kept": round(float(np.mean([outputs[i].kept for i in rows])), 4),
            "foot_sliding_cm_s": round(float(np.mean([outputs[i].sliding for i in rows])), 2),
        }
        for source, rows in sorted(by_source.items())
    }
    said = {(o.item.name, o.name): p for o, p in zip(outputs, predicted, strict=True)}
    variants = [i for i, o in enumerate(outputs) if o.item.name != o.item.original]
    originals = set(range(len(outputs))) - set(variants)
    figures["top1_originals_only"] = _share([hits[i] for i in sorted(originals)])
    figures["variants_agree"] = _share(
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
        content_kept_share=_share([k >= KEPT for k in kept]),
        foot_sliding_cm_s=round(float(np.mean([o.sliding for o in outputs])), 2),
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
    }


# --------------------------------------------------------------------------- evaluation


def evaluate(
    halves: tuple[str, ...],
    families: tuple[str, ...] = FAMILIES,
    classifier_cache: Path | None = None,
    limit: int | None = None,
    log=print,
    pinned: Path | None = None,
    pin: bool = False,
) -> dict[str, dict]:
    """The report of each of ``halves`` (see the module docstring); ``limit``: only the first
    N items of each half (a smoke run). The judge is the ``pinned`` file where it exists,
    else trained (and kept in ``classifier_cache``); ``pin`` writes it to
    :data:`PINNED_JUDGE`."""
    from training.data import load_bandai
    from training.measuring_machine import measuring_machine

    started = time.time()
    clips = load_bandai()
    judge = judge_for(clips, classifier_cache, pinned)
    if pin:
        pin_judge(judge, clips)
    seconds = {"judge": round(time.time() - started, 1)}
    source = pinned if pinned is not None and pinned.exists() else "trained"
    log(f"judge ready ({source}, {seconds['judge']} s)")
    t = time.time()
    real = real_bandai(clips)
    ref = reference(judge)
    items = {h: v[:limit] if limit else v for h, v in load_items(halves).items()}
    seconds["references and items"] = round(time.time() - t, 1)
    loaded = {e: load_engine(e) for e in {ENGINE_OF.get(f, f) for f in families}}
    engines = {f: loaded[ENGINE_OF.get(f, f)] for f in families}
    adapters = {
        "translator-clip": ByStyleClip(clips),
        "translator-video": ByStyleVideo(clips),
        "translator-clip-unseen": ByStyleClip(clips, unseen=True),
        "translator-video-unseen": ByStyleVideo(clips, unseen=True),
    }
    outputs: dict[str, list[Output]] = {}
    jitter: dict[str, dict] = {}
    for f in families:
        t = time.time()
        everything = [i for h in halves for i in items[h]]
        outputs[f] = send(f, engines[f][0], everything, judge, real, log, adapters.get(f))
        if f in ADAPTERS:  # the families with networks of their own
            jitter[f] = held_out_jitter(f, engines[f][0], clips)
        seconds[f"{f} transfers and judging"] = round(time.time() - t, 1)
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
            "real_bandai": {
                "leave_action_out": ref,
                "spread": round(real.spread, 4),
                "spread_by_dataset": real.spread_by_dataset,
                "foot_sliding_cm_s": round(real.sliding, 2),
            },
            "machine": measuring_machine(),
            "measured": time.strftime("%Y-%m-%d"),
            "seconds": {**seconds, "total": round(time.time() - started, 1)},
        }
    return reports


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{x:.0%}"


def markdown(report: dict) -> str:
    """Tables of one half's report."""
    fams, ref = report["families"], report["real_bandai"]["leave_action_out"]
    unchanged, real = report["unchanged"], report["real_bandai"]
    counts = ", ".join(f"{s} {n}" for s, n in report["items_by_source"].items())
    lines = [
        f"### Foreign content, {report['half']} half: {report['items']} items of "
        f"{len(report['takes'])} takes ({counts}); "
        f"{len(report['styles'])} merged styles, chance {report['chance']:.1%}",
        "",
        "| | "
        + " | ".join(f"{f} ({v['model_version']})" for f, v in fams.items())
        + " | content unchanged | real Bandai, leave-action-out |",
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
    row(
        "jerk against real mocap, Bandai's held-out takes in their own style",
        lambda v: f"{v['held_out_jitter']['ratio']:.2f}" if v.get("held_out_jitter") else "-",
        "-",
        "1",
    )
    lines += [
        "",
        "| style (merged) | "
        + " | ".join(f"{f} recall" for f in fams)
        + " | unchanged: share predicted | real: leave-action-out recall |",
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
    lines += [
        "",
        f"Machine: {report['machine']}. Seconds: "
        + ", ".join(f"{k} {v}" for k, v in report["seconds"].items())
        + ".",
    ]
    return "\n".join(lines)


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
        "--out-dir", type=Path, default=REPO / "runs/eval", help="writes foreign-<half>.json here"
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
    args = p.parse_args(argv)
    halves = HALVES if args.half == "both" else (args.half,)
    reports = evaluate(
        halves,
        tuple(args.families),
        args.classifier_cache,
        args.limit,
        pinned=None if args.pin_judge else args.judge,
        pin=args.pin_judge,
    )
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for h, report in reports.items():
        print()
        print(markdown(report))
        (args.out_dir / f"foreign-{h}.json").write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    # as the imported module, so the pickled judge names ``training.eval_foreign`` classes
    from training import eval_foreign

    raise SystemExit(eval_foreign.main())

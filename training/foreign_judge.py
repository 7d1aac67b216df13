"""The style judge of the foreign evaluation (``training.eval_foreign``) and its reference
figures on real Bandai takes.

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

A studio's library (``eval_foreign --library``) has a judge of its own,
:func:`train_library_judge`: the same classifier on the library's takes and style labels,
its reference the takes ``labels.csv`` holds out (:func:`held_out_reference`).

Style or actor: in Bandai dataset-2 each style is one actor, three actors sharing seven
styles. Every clip is retargeted onto one canonical skeleton (bone lengths averaged over
the data) before features are taken, so body proportions, the plainest trace of an
actor, never reach the judge; what may remain is the actor's manner. The within-actor
figures measure it: over held-out dataset-2 clips of a group of styles one actor
performed, how often the judge, restricted to that group's styles, names the right one. A
judge that read the actor would be at chance there.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import json
import pickle
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import canonical as C
from motion.skeleton import Motion
from motion.styles import canonical_style
from training import judges
from training.judges import ConvClipClassifier, frame_features

REPO = Path(__file__).resolve().parent.parent

PINNED_JUDGE = REPO / "training" / "foreign_judge.pt"  # the yardstick, committed
CHECK_TAKES = 6  # real takes a pinned judge re-judges when loaded
ACTOR_GROUPS = (
    ("active", "elderly", "exhausted"),
    ("feminine", "youthful"),
    ("masculine", "normal"),
)


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


def held_out_record(clip, style: str, group: str, logp: np.ndarray) -> dict:
    """One real take the judge did not learn from, with how its stand-in named it."""
    return {
        "take": clip.take,
        "dataset": clip.dataset,
        "content": clip.content,
        "style": style,
        "group": group,
        "logp": logp,
    }


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
            judge.held_out.append(
                held_out_record(clips[i], labels[i], group, fold.log_probabilities(feats[i]))
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
    return _cached(path, lambda: train_judge(clips))


def _cached(path: Path, make) -> StyleJudge:
    if path.exists():
        with path.open("rb") as f:
            return pickle.load(f)
    judge = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    with partial.open("wb") as f:
        pickle.dump(judge, f)
    partial.replace(path)
    return judge


def train_library_judge(clips: list) -> StyleJudge:
    """The judge of a studio's library (``training.library`` clips): the classifier of every
    take, and of the mirror image of each whose ``mirror_ok``, by the library's own style
    labels (no names merged). Its reference (``held_out``, group ``held-out``): what a twin
    trained without the takes ``labels.csv`` holds out makes of each of them. Those takes
    share performers and actions with the rest, so the reference is nearer a ceiling than
    Bandai's leave-action-out one."""
    from training.bandai_library import held_out_clip

    feats = [frame_features(c.motion) for c in clips]
    mirrors = {
        i: frame_features(C.mirrored(c.motion))
        for i, c in enumerate(clips)
        if c.extra.get("mirror_ok", True)
    }
    labels = [c.style for c in clips]

    def classifier(rows: list[int]) -> ConvClipClassifier:
        flipped = [i for i in rows if i in mirrors]
        return ConvClipClassifier(
            [feats[i] for i in rows] + [mirrors[i] for i in flipped],
            [labels[i] for i in rows] + [labels[i] for i in flipped],
        )

    held = [i for i, c in enumerate(clips) if held_out_clip(c)]
    if not held:
        raise ValueError(
            "the library holds no take out (labels.csv's held_out): "
            "no real take is left to check its judge on"
        )
    judge = StyleJudge(classifier(list(range(len(clips)))), [])
    twin = classifier([i for i in range(len(clips)) if i not in set(held)])
    if twin.classes != judge.classes:
        raise ValueError(
            f"style(s) {', '.join(sorted(set(judge.classes) - set(twin.classes)))} "
            "have only held-out takes: the judge's reference could not name them"
        )
    for i in held:
        judge.held_out.append(
            held_out_record(clips[i], labels[i], "held-out", twin.log_probabilities(feats[i]))
        )
    return judge


def library_judge_for(clips: list, cache: Path | None) -> StyleJudge:
    """:func:`train_library_judge` of a library's ``clips``, kept in ``cache`` under
    :func:`judge_key` and that function's code."""
    if cache is None:
        return train_library_judge(clips)
    key = hashlib.sha256((judge_key(clips) + inspect.getsource(train_library_judge)).encode())
    return _cached(
        Path(cache) / f"library-judge-{key.hexdigest()[:16]}.pkl",
        lambda: train_library_judge(clips),
    )


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


def share(xs) -> float | None:
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
        s: share([h for h, r in zip(hits, requested, strict=True) if r == s])
        for s in sorted(set(requested))
    }
    counts = Counter(predicted)
    most, most_n = counts.most_common(1)[0] if counts else (None, 0)
    confusion: dict[str, dict[str, int]] = {}
    for r, p in zip(requested, predicted, strict=True):
        confusion.setdefault(r, Counter())[p] += 1
    return {
        "n": len(requested),
        "top1": share(hits),
        "top3": share(top3),
        "top1_mean_per_style": share(list(recall.values())),
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
            "recall_within_group": share(
                [n == h["style"] for n, h in zip(named, rows, strict=True)]
            ),
            "chance": round(1 / len(group), 4),
            "top1": share(top1),
        }
    return out


def reference(judge: StyleJudge) -> dict:
    """The judge's leave-action-out figures on real Bandai takes ("real clips")."""
    held = judge.held_out
    figures = held_out_reference(judge)
    figures.pop("confusion")
    figures["by_action_group"] = {
        g: share(
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


def held_out_reference(judge: StyleJudge) -> dict:
    """A library judge's figures on the library's held-out takes (:func:`train_library_judge`)."""
    held = judge.held_out
    figures = recognition(
        [h["style"] for h in held], np.array([h["logp"] for h in held]), judge.classes
    )
    figures.pop("predicted")
    return figures

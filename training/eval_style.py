"""Evaluation of the style families as shipped (aberman2020 translator, holden2017 fast
networks): style and content recognition of their outputs, and foot skating.

    python -m training.eval_style translator|fast|all [--json PATH] [--limit N] [--no-mirror]
        [--classifier-cache DIR] [--manifest] [--strength S]

For a family, the held-out takes are the Bandai takes its training never saw (its bundle's
``split.json``): 51 takes for the translator, 73 for the fast networks, too few for a
leave-one-take-out classifier to see every style and content. So the classifiers learn
from the first half of every held-out take:

- content: balanced logistic regression on 1.5-second windows of pose, speed and
  trajectory statistics, a clip's label the argmax of its windows' mean log-probability;
- content (conv): the convolutional networks below, trained on the content labels (no
  mirrors: they swap left and right actions). They recognise the content of real target
  clips better than the logistic regression does (51.6% against 38.7% on the
  translator's takes), so both are reported: with 1-6 held-out takes per content, each
  classifier also learns the styles its content was performed in (bow, byebye, dash,
  walk-back, walk-right and raise-up-right-hand are held out in one style each);
- content (all takes): the same networks trained on the held-out first halves and on the
  family's training takes too (``FoldedClassifier``: three folds by take, a clip judged
  beside a real target by the fold that never saw that target's take). With each held-out
  content seen in 7-19 styles they recognise about 70% of the real target clips: the
  yardstick of content that does not mistake a new style for a lost action. It departs
  from "classifiers learn from held-out takes only", so the two columns above stay;
- content (unseen takes): the same networks, the held-out first halves folded by take as
  well (``content_unseen``), so that every clip is judged by networks that never saw the
  take its motion comes from: a transfer and its unchanged content clip by those that never
  saw the content's take, a real target by those that never saw its own. The columns above
  judge the unchanged clip by networks that learnt its take's first half, so it is read
  by the performer's manner as much as by the action, which a transfer to another style
  is meant to change;
- style (reported as style accuracy): small convolutional networks on 1.6-second windows
  of root-local joint positions, their velocities and the root's motion
  (``ConvClipClassifier``); they recognise real clips of other takes better than the
  logistic regression does (about half of them against a third, on the translator's
  takes);
- style (linear): the logistic regression as for content, the earlier yardstick, still
  reported beside it.

Both style classifiers also learn from the mirror images of the first halves (left and
right swapped: a style has no side; with 1-3 takes per style the mirrors raised the
linear classifier's accuracy on real clips of other takes from 24% to 34%).

Everything is judged on second halves: each held-out take's second half is sent to every
style through the shipped engine, exactly as the service runs it (onnxruntime, time warp
and foot clean-up), and the output is scored against the target style and the take's
content. Baselines, judged by the same classifiers:

- ``unchanged``: the output is the content clip itself;
- ``real target``: the output is a real Bandai clip of X's content in the target style
  (from the family's training takes, which the classifiers never saw), where one exists;
- ``real held-out``: each held-out clip against its own labels (the classifiers' ceiling).

Style read as the content's is the share of clips the style classifier gives the content
clip's own style, where that is not the target: the classifier learnt each held-out take's
first half, so a transfer of its second half that keeps that take's manner is read as its
style, which a real target, another take, is not (on 0.1.71412, 18% of the transfers with
a real target against 9% of those real targets; 90% of the unchanged clips).

The gaps that "Done when" weighs (style and content of transfers against real targets,
content against the unchanged clips) come with 95% intervals from a bootstrap that
resamples content takes, the clips of a take being judged by classifiers that learnt its
first half (``gaps``; on 0.1.71412, its hips grounded on the content's floor, style where
a real target exists is 0.4 points above the real targets, -3.4 to +4.2, and content 9.4
points below them, 3.8 to 15.6).

The transfers and real targets are also split by action, hand actions (raise, wave) and
the rest, and the transfers by whether a real target exists: to the twelve styles that
never raise or wave a hand in Bandai none does, and only the classifiers judge them.

Foot skating is foot sliding as Zhang et al. (2018) measure it, in cm/s: feet and toes'
horizontal speed weighted by how close they are to the clip's ground (within 2.5 cm), so
it needs no contact labels and judges generated and real clips alike.

Hand reach (cm) is how high the higher hand gets above the head (95th percentile), over
the clips whose content raises or waves a hand: what a transfer keeps of those actions.

Two measures of content need no classifier, so the styles and actions a classifier has
seen together cannot sway them. Each compares a clip with the content clip it was made
from:

- hand use error: over hand actions, how much the share of frames each hand spends above
  the head differs from the content's, averaged over both hands (a wave of the left hand
  that also lifts the right one scores about 50%);
- turning error: how far the degrees the body turns over the clip differ (a walk-turn
  that goes straight scores about 45).

The content classifiers also report their commonest confusions per row.

Content (all takes, merged) counts as one action what the two Bandai datasets tell apart
only by which dataset a style is in, and the strict figure stays beside it:

- walk, walk-turn-left and walk-turn-right. Dataset 1 has no turning walks, so the
  classifier has never seen its twelve styles turn, and a turning walk sent to one of them
  is often read as a walk; the turning error says whether it turns;
- dataset 1's bye and dataset 2's wave-right-hand, and dataset 1's byebye and dataset 2's
  wave-both-hands: one action under two names. Measured on all Bandai clips, the share of
  frames each hand is above the head (left, right) and its speed relative to the hips
  (cm/s) are bye 0.00, 0.55 and 10, 75; wave-right-hand 0.00, 0.60 and 10, 97; byebye
  0.62, 0.63 and 87, 86; wave-both-hands 0.57, 0.61 and 104, 101
  (``test_merged_names_use_the_hands_alike``). A wave sent to a dataset-1 style is often
  read as that dataset's name for it.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import pickle
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from motion import canonical as C
from motion import contacts as CT
from motion import features as Fe
from motion import kinematics as K
from motion.skeleton import Motion

REPO = Path(__file__).resolve().parent.parent
WINDOW = 45  # frames (1.5 s at 30 fps)
HOP = 15
FAMILIES = ("translator", "fast")
MISSED_SHOWN = 12  # the commonest content confusions reported per row
# one action in the merged content figure (see the module's docstring)
SAME_ACTION = {"walk-turn-left": "walk", "walk-turn-right": "walk",
               "bye": "wave-right-hand", "byebye": "wave-both-hands"}  # fmt: skip


# --------------------------------------------------------------------------- features


_MIRROR = [C.INDEX[n[:-1] + {"L": "R", "R": "L"}[n[-1]]] if n[-2:] in ("_L", "_R") else i
           for i, n in enumerate(C.JOINTS)]  # fmt: skip


def window_features(
    motion: Motion, window: int = WINDOW, hop: int = HOP, mirror: bool = False
) -> np.ndarray:
    """``(W, D)`` statistics of overlapping windows of a canonical 30 fps motion: mean and
    std of root-local joint positions, mean and std of joint speeds, root speed, turning
    speed and hips height (all facing-invariant); of its mirror image (left and right
    swapped) with ``mirror``."""
    gpos = K.global_positions(motion)
    if mirror:
        gpos = gpos[:, _MIRROR] * np.array([-1.0, 1.0, 1.0])
    facing = Fe.facing(gpos)
    local = K.root_local(gpos, gpos[:, 0], facing).reshape(len(gpos), -1)
    speed = np.linalg.norm(K.velocities(local.reshape(len(gpos), -1, 3), motion.fps), axis=-1)
    root_vel, turn = K.root_velocities(gpos[:, 0], facing, motion.fps)
    per_frame = np.concatenate(
        [local, speed, root_vel, np.abs(turn)[:, None], gpos[:, :1, 1]], axis=1
    )
    frames = len(per_frame)
    size = min(window, frames)
    starts = range(0, max(frames - size, 0) + 1, hop)
    rows = []
    for s in starts:
        w = per_frame[s : s + size]
        rows.append(np.concatenate([w.mean(0), w.std(0)]))
    return np.asarray(rows, dtype=np.float64)


def skating(motion: Motion) -> float:
    """Foot sliding in cm/s (``motion.contacts.canonical_foot_sliding``)."""
    return CT.canonical_foot_sliding(motion)


_HANDS, _HEAD = [C.INDEX["Hand_L"], C.INDEX["Hand_R"]], C.INDEX["Head"]


def _above_head(motion: Motion) -> np.ndarray:
    """Height of each hand (left, right) above the head per frame, ``(frames, 2)``."""
    gpos = K.global_positions(motion)
    return gpos[:, _HANDS, 1] - gpos[:, [_HEAD], 1]


def hand_reach(motion: Motion) -> float:
    """How high the higher hand gets above the head, in cm (the larger of the two hands'
    95th percentile of height above the head): what a raised or waving hand keeps."""
    return float(np.percentile(_above_head(motion), 95, axis=0).max())


def hands_up(motion: Motion) -> tuple[float, float]:
    """The fraction of frames each hand (left, right) is above the head."""
    return tuple(float(v) for v in (_above_head(motion) > 0).mean(axis=0))


def turning(motion: Motion) -> float:
    """How far the body turns about the vertical over the clip, in degrees (signed)."""
    gpos = K.global_positions(motion)
    forward = K.facing_directions(gpos, *Fe.FACING_JOINTS)  # unsmoothed: ends stay whole
    heading = np.unwrap(np.arctan2(forward[:, 0], forward[:, 2]))
    return float(np.degrees(heading[-1] - heading[0]))


def merged(content: str) -> str:
    """The name ``content`` shares with the actions it is merged with (:data:`SAME_ACTION`)."""
    return SAME_ACTION.get(content, content)


def raises_a_hand(content: str) -> bool:
    """Bandai's hand actions: raise-up-*-hand(s), wave-*-hand(s)."""
    return content.endswith(("-hand", "-hands"))


_BODY_MIRROR = [_MIRROR[j] - 1 for j in Fe.BODY]  # Fe.BODY is every joint but joint_Root (0)


def frame_features(motion: Motion, mirror: bool = False) -> np.ndarray:
    """``(F, 130)`` float32 per frame of a canonical 30 fps motion: root-local body joint
    positions (leg lengths, facing frame: ``motion.features``' 3D style input), their
    velocities, and the root channels (hips height, velocity sideways and forward,
    turning); of its mirror image with ``mirror``."""
    enc = Fe.encode(motion)
    pos = enc.style3d.reshape(len(enc.style3d), -1, 3)
    root = enc.content[:, Fe.ROTATION_CHANNELS :].copy()
    if mirror:
        pos = pos[:, _BODY_MIRROR] * np.array([-1.0, 1.0, 1.0], dtype=np.float32)
        root[:, [1, 3]] *= -1.0  # sideways velocity, turning
    vel = np.gradient(pos, axis=0) * motion.fps if len(pos) > 1 else np.zeros_like(pos)
    flat = [pos.reshape(len(pos), -1), vel.reshape(len(pos), -1), root]
    return np.concatenate(flat, axis=1).astype(np.float32)


class ConvClipClassifier:
    """Small 1D convolutional networks on :func:`frame_features` of 48-frame windows (three
    convolutions, mean over time, dropout, linear), trained on random windows with Gaussian
    noise, classes drawn uniformly; one network per seed, and a clip's label is the argmax
    of its windows' mean log-probability over all of them (one seed alone moves the
    figures by ~4 points). On real clips it is the stronger yardstick of style: trained
    on the translator's held-out first halves, it recognises about half of the real clips
    of other takes, the logistic regression on window statistics a third.

    Each network trains on one thread, so the same data gives the same network: on two,
    one of three trainings of 1,500 steps came out different, and the content figures of
    one model moved by up to 4 points between two evaluations. On one thread the translator
    evaluation's classifiers take 537 s instead of 433 s, and two evaluations from empty
    caches gave identical reports.
    """

    WINDOW = 48
    HOP = 15

    def __init__(
        self,
        features: list[np.ndarray],
        labels: list[str],
        seeds: tuple[int, ...] = (0, 1, 2),
        steps: int = 1500,
    ) -> None:
        x = np.concatenate(features)
        self.mean, self.std = x.mean(axis=0), x.std(axis=0) + 1e-3
        self.classes = sorted(set(labels))
        y = np.array([self.classes.index(lab) for lab in labels])
        clips = [self._prepare(f) for f in features]
        self.nets = [self._train(clips, y, seed, steps) for seed in seeds]

    def _train(self, clips: list[np.ndarray], y: np.ndarray, seed: int, steps: int):
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # see the class docstring
        try:
            return self._train_on_this_thread(clips, y, seed, steps)
        finally:
            torch.set_num_threads(threads)

    def _train_on_this_thread(self, clips: list[np.ndarray], y: np.ndarray, seed: int, steps: int):
        import torch
        import torch.nn.functional as F
        from torch import nn

        torch.manual_seed(seed)
        rng = np.random.default_rng(seed)
        net = nn.Sequential(
            nn.Conv1d(clips[0].shape[1], 64, 5, padding=2), nn.LeakyReLU(0.2),
            nn.Conv1d(64, 96, 4, stride=2, padding=1), nn.LeakyReLU(0.2),
            nn.Conv1d(96, 128, 4, stride=2, padding=1), nn.LeakyReLU(0.2),
            nn.AdaptiveAvgPool1d(1), nn.Flatten(), nn.Dropout(0.3),
            nn.Linear(128, len(self.classes)),
        )  # fmt: skip
        opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=1e-4)
        by_class = [np.flatnonzero(y == k) for k in range(len(self.classes))]
        for _ in range(steps):
            chosen = [rng.choice(by_class[k]) for k in rng.integers(len(self.classes), size=64)]
            batch = np.stack(
                [clips[i][s : s + self.WINDOW]
                 for i in chosen for s in [rng.integers(len(clips[i]) - self.WINDOW + 1)]]
            )  # fmt: skip
            xb = torch.from_numpy(batch).transpose(1, 2)
            logits = net(xb + 0.1 * torch.randn_like(xb))
            loss = F.cross_entropy(logits, torch.from_numpy(y[chosen]))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        return net.eval()

    def _prepare(self, features: np.ndarray) -> np.ndarray:
        x = ((features - self.mean) / self.std).astype(np.float32)
        return np.pad(x, ((0, max(0, self.WINDOW - len(x))), (0, 0)), mode="edge")

    def log_probabilities(self, features: np.ndarray) -> np.ndarray:
        """``(classes,)`` a clip's log-probability of each of :attr:`classes`, averaged over
        its windows and the networks (the whole ranking: top-k needs more than the argmax)."""
        import torch
        import torch.nn.functional as F

        x = self._prepare(features)
        starts = range(0, len(x) - self.WINDOW + 1, self.HOP)
        windows = torch.from_numpy(np.stack([x[s : s + self.WINDOW] for s in starts]))
        with torch.no_grad():
            logp = sum(
                F.log_softmax(net(windows.transpose(1, 2)), dim=-1).mean(dim=0) for net in self.nets
            )
        return (logp / len(self.nets)).numpy().astype(np.float64)

    def predict(self, features: np.ndarray) -> str:
        return str(self.classes[int(np.argmax(self.log_probabilities(features)))])


class FoldedClassifier:
    """:class:`ConvClipClassifier` s that also learn from takes a judged clip may be compared
    with: the takes are split in ``folds`` folds (by a hash of the take), fold ``k``'s
    networks learn from ``shared`` clips and from every take outside fold ``k``, and
    judge what is compared with a take of fold ``k`` (:meth:`fold_of`), so no clip is
    judged by networks that learnt from its take."""

    def __init__(
        self,
        shared: list[np.ndarray],
        shared_labels: list[str],
        features: list[np.ndarray],
        labels: list[str],
        takes: list[str],
        folds: int = 3,
        **conv_options,
    ) -> None:
        self.folds = folds
        self.classifiers = []
        for k in range(folds):
            keep = [i for i, take in enumerate(takes) if self.fold_of(take) != k]
            self.classifiers.append(
                ConvClipClassifier(
                    shared + [features[i] for i in keep],
                    shared_labels + [labels[i] for i in keep],
                    **conv_options,
                )
            )

    def fold_of(self, take: str) -> int:
        return zlib.crc32(take.encode()) % self.folds

    def predict(self, features: np.ndarray, fold: int) -> str:
        return self.classifiers[fold].predict(features)


class ClipClassifier:
    """Logistic regression on window features; a clip's label is the argmax of its windows'
    mean log-probability. Classes are weighted by their inverse frequency: Bandai 2 has
    many takes of few styles, and an unweighted classifier answers those styles for
    anything it is unsure of."""

    def __init__(self, features: list[np.ndarray], labels: list[str]) -> None:
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        x = np.concatenate(features)
        y = np.concatenate([[lab] * len(f) for f, lab in zip(features, labels, strict=True)])
        self.model = make_pipeline(
            StandardScaler(), LogisticRegression(C=1.0, max_iter=3000, class_weight="balanced")
        )
        self.model.fit(x, y)
        self.classes = list(self.model.classes_)

    def predict(self, features: np.ndarray) -> str:
        logp = np.log(np.clip(self.model.predict_proba(features), 1e-12, 1.0)).mean(axis=0)
        return str(self.classes[int(np.argmax(logp))])


# --------------------------------------------------------------------------- families


def load_engine(family: str):
    """The shipped engine of ``family``, loaded as the service loads it."""
    from service.config import Settings
    from service.engines.fast import FastEngine
    from service.engines.translator import TranslatorEngine
    from service.manifest import load_manifest

    settings = Settings()
    manifest = load_manifest(settings.models_dir)
    entry = next(m for m in manifest.models if m.family == family)
    cls = {"translator": TranslatorEngine, "fast": FastEngine}[family]
    engine = cls(entry, settings.models_dir, settings)
    engine.load()
    return engine, entry, settings.models_dir


def held_out_takes(family: str) -> set[str]:
    """The Bandai takes the shipped ``family``'s training never saw (its ``split.json``)."""
    from service.config import Settings
    from service.manifest import load_manifest

    models_dir = Settings().models_dir
    entry = next(m for m in load_manifest(models_dir).models if m.family == family)
    split = next(f.path for f in entry.files if f.path.endswith("split.json"))
    data = json.loads((models_dir / split).read_text())
    return set(data.get("val_takes") or data["validation_takes"])


def style_names(family: str, engine) -> list[str]:
    if family == "translator":
        return list(engine.style_names)
    return sorted(engine.style_info)


def check_strength(family: str, strength: float) -> None:
    """Raise ``ValueError`` unless ``family`` can transfer at ``strength``: the translator
    from 0 to 1 (the API's ``strength``), the fast networks only at 1 (they have none)."""
    if family == "translator" and not 0.0 <= strength <= 1.0:
        raise ValueError(f"strength must be within 0 and 1, got {strength}")
    if family != "translator" and strength != 1.0:
        raise ValueError(f"the {family} family has no strength: only 1, got {strength}")


def transfer(family: str, engine, canon: Motion, style: str, strength: float = 1.0) -> Motion:
    """``canon`` in ``style`` through the shipped engine, as the service runs it; the
    translator at ``strength`` (the API's ``strength``, 1 by default)."""
    from service.metrics import StageTimer

    check_strength(family, strength)
    if family == "translator":
        target = engine.code_of_name(style)
        return engine.transfer(
            canon,
            target.code,
            strength=strength,
            style_velocity=target.velocity,
            style_speed=target.speed,
        ).motion
    return engine.stylize(canon, style, StageTimer(engine.name))


# --------------------------------------------------------------------------- evaluation


@dataclass(frozen=True)
class Verdict:
    """What the classifiers make of one clip: its style and its content by the
    convolutional and by the linear classifiers; its foot skating (cm/s) and hand reach
    (cm, :func:`hand_reach`)."""

    style: str
    style_linear: str
    content: str
    content_conv: str
    content_all: str
    content_unseen: str
    skating: float
    hand_reach: float
    hands_up: tuple[float, float]
    turning: float


@dataclass
class Tally:
    style: list[bool] = field(default_factory=list)
    style_linear: list[bool] = field(default_factory=list)
    content: list[bool] = field(default_factory=list)
    content_conv: list[bool] = field(default_factory=list)
    content_all: list[bool] = field(default_factory=list)
    content_all_merged: list[bool] = field(default_factory=list)  # SAME_ACTION merged
    content_unseen: list[bool] = field(default_factory=list)
    skating: list[float] = field(default_factory=list)
    hand_reach: list[float] = field(default_factory=list)  # only clips of hand actions
    # against the content clip: share of frames a hand is above the head (hand actions
    # only), degrees turned
    hand_use_error: list[float] = field(default_factory=list)
    turning_error: list[float] = field(default_factory=list)
    # (true content, what the all-takes classifier said) where they differ
    missed: Counter = field(default_factory=Counter)
    # style read as the content clip's own, where that is not the target style
    style_as_source: list[bool] = field(default_factory=list)
    takes: list[str | None] = field(default_factory=list)  # the content take of each clip

    def add(
        self,
        verdict: Verdict,
        style: str,
        content: str,
        source: Verdict,
        source_style: str | None = None,
        take: str | None = None,
    ) -> None:
        """``verdict`` of a clip meant as ``content`` in ``style``; ``source``: the content
        clip's own verdict, ``source_style`` its style label, ``take`` its take."""
        self.takes.append(take)
        self.style.append(verdict.style == style)
        if source_style is not None and source_style != style:
            self.style_as_source.append(verdict.style == source_style)
        self.style_linear.append(verdict.style_linear == style)
        self.content.append(verdict.content == content)
        self.content_conv.append(verdict.content_conv == content)
        self.content_all.append(verdict.content_all == content)
        self.content_all_merged.append(merged(verdict.content_all) == merged(content))
        self.content_unseen.append(verdict.content_unseen == content)
        if verdict.content_all != content:
            self.missed[content, verdict.content_all] += 1
        self.skating.append(verdict.skating)
        self.turning_error.append(abs(verdict.turning - source.turning))
        if raises_a_hand(content):
            self.hand_reach.append(verdict.hand_reach)
            error = np.abs(np.subtract(verdict.hands_up, source.hands_up)).mean()
            self.hand_use_error.append(float(error))

    def summary(self) -> dict:
        def mean(xs: list) -> float | None:
            return round(float(np.mean(xs)), 4) if xs else None

        skate, reach = mean(self.skating), mean(self.hand_reach)
        return {
            "n": len(self.style),
            "style_accuracy": mean(self.style),
            "style_accuracy_linear": mean(self.style_linear),
            "style_as_source": mean(self.style_as_source),
            "content_accuracy": mean(self.content),
            "content_accuracy_conv": mean(self.content_conv),
            "content_accuracy_all_takes": mean(self.content_all),
            "content_accuracy_all_takes_merged": mean(self.content_all_merged),
            "content_accuracy_unseen_takes": mean(self.content_unseen),
            "foot_skating_cm_s": round(skate, 2) if skate is not None else None,
            "hand_actions": len(self.hand_reach),
            "hand_reach_cm": round(reach, 1) if reach is not None else None,
            "hand_use_error": mean(self.hand_use_error),
            "turning_error_deg": round(float(np.mean(self.turning_error)), 1)
            if self.turning_error
            else None,
            "content_missed_all_takes": {
                f"{a} -> {b}": k for (a, b), k in self.missed.most_common(MISSED_SHOWN)
            },
        }


def halves(motion: Motion) -> tuple[Motion, Motion]:
    """First and second half of a clip: classifiers learn from the first halves of the
    held-out takes, everything is judged on second halves."""
    mid = motion.num_frames // 2
    return motion.slice(0, mid), motion.slice(mid, motion.num_frames)


@dataclass
class Classifiers:
    """The judges of one evaluation (see the module's docstring)."""

    content: ClipClassifier
    content_conv: ConvClipClassifier
    content_all: FoldedClassifier
    content_unseen: FoldedClassifier
    style_linear: ClipClassifier
    style_conv: ConvClipClassifier


def train_classifiers(held_list: list, training: list, mirror: bool = True) -> Classifiers:
    """Classifiers of the held-out takes' first halves (``content_all``: and of the
    ``training`` takes, in folds; ``content_unseen``: of both, all in folds)."""
    first = [halves(c.motion)[0] for c in held_list]
    train_feats = [window_features(m) for m in first]
    contents = [c.content for c in held_list]
    styles_of = [c.style for c in held_list]
    frames = [frame_features(m) for m in first]
    content = ClipClassifier(train_feats, contents)
    content_conv = ConvClipClassifier(frames, contents)
    training_frames = [frame_features(c.motion) for c in training]
    training_contents, training_takes = [c.content for c in training], [c.take for c in training]
    content_all = FoldedClassifier(
        frames, contents, training_frames, training_contents, training_takes
    )
    content_unseen = FoldedClassifier(
        [],
        [],
        frames + training_frames,
        contents + training_contents,
        [c.take for c in held_list] + training_takes,
    )
    if mirror:  # a style has no side: the mirror images double the style classifiers' data
        train_feats = train_feats + [window_features(m, mirror=True) for m in first]
        frames = frames + [frame_features(m, mirror=True) for m in first]
        styles_of = styles_of + styles_of
    return Classifiers(
        content,
        content_conv,
        content_all,
        content_unseen,
        ClipClassifier(train_feats, styles_of),
        ConvClipClassifier(frames, styles_of),
    )


def _feature_sources() -> list[Path]:
    """The ``motion`` package's files: the classifiers' features are computed by it."""
    return sorted((REPO / "motion").glob("*.py"))


def classifier_code_key() -> str:
    """A hash of the code that makes the classifiers (this module's features, classifiers
    and their training, and the ``motion`` package they read motion through), so that an
    edit of the report or the transfers keeps a cached set and an edit of what judges
    retrains it."""
    key = hashlib.sha256()
    for part in (window_features, frame_features, halves, Classifiers, train_classifiers,
                 ConvClipClassifier, FoldedClassifier, ClipClassifier):  # fmt: skip
        key.update(inspect.getsource(part).encode())
    key.update(repr((WINDOW, HOP, _MIRROR, _BODY_MIRROR)).encode())
    for path in _feature_sources():
        key.update(path.read_bytes())
    return key.hexdigest()


def classifiers_for(
    held_list: list, training: list, mirror: bool, cache: Path | None = None
) -> Classifiers:
    """:func:`train_classifiers`, kept in ``cache`` (a folder) when given: about ten minutes
    of a translator evaluation's thirteen on two cores. A kept set is used again only for
    the same takes, labels and lengths and the same code that makes classifiers
    (:func:`classifier_code_key`)."""
    if cache is None:
        return train_classifiers(held_list, training, mirror)
    key = hashlib.sha256(classifier_code_key().encode())
    for group in (held_list, training):
        takes = sorted((c.take, c.style, c.content, len(c.lrot)) for c in group)
        key.update(json.dumps(takes).encode())
    key.update(str(mirror).encode())
    path = Path(cache) / f"classifiers-{key.hexdigest()[:16]}.pkl"
    if path.exists():
        with path.open("rb") as f:
            return pickle.load(f)
    classifiers = train_classifiers(held_list, training, mirror)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    with partial.open("wb") as f:
        pickle.dump(classifiers, f)
    partial.replace(path)
    return classifiers


def evaluate(
    family: str,
    takes_of: str | None = None,
    limit: int | None = None,
    log=print,
    mirror: bool = True,
    classifier_cache: Path | None = None,
    strength: float = 1.0,
) -> dict:
    """The report of ``family`` on the held-out takes of ``takes_of`` (default its own);
    ``classifier_cache``: a folder keeping the trained classifiers (see
    :func:`classifiers_for`); ``strength``: the translator's transfers at that strength."""
    from training.data import load_bandai

    check_strength(family, strength)
    engine, entry, _ = load_engine(family)
    takes_of = takes_of or family
    held = held_out_takes(takes_of)
    own = held_out_takes(family)
    styles = style_names(family, engine)
    clips = load_bandai()
    held_list = [c for c in clips if c.take in held]
    real_of = {}  # (content, style) -> a real clip from the family's training takes
    for c in clips:
        if c.take not in held:
            real_of.setdefault((c.content, c.style), c)

    started = time.time()
    training = [c for c in clips if c.take not in held]
    clf = classifiers_for(held_list, training, mirror, classifier_cache)
    content_clf, content_conv, content_all = clf.content, clf.content_conv, clf.content_all
    content_unseen = clf.content_unseen
    style_linear, style_conv = clf.style_linear, clf.style_conv
    log(f"classifiers ready ({time.time() - started:.0f} s)")
    judged: dict[str, Verdict] = {}  # by take; the folded classifier's answer by take and fold
    judged_all: dict[tuple[str, int], str] = {}

    def verdict(motion: Motion, fold: int, take: str) -> Verdict:
        """``fold``: of ``content_all`` (see below); ``take``: where ``motion`` comes from,
        whose fold of ``content_unseen`` never saw it."""
        f, per_frame = window_features(motion), frame_features(motion)
        return Verdict(
            style_conv.predict(per_frame),
            style_linear.predict(f),
            content_clf.predict(f),
            content_conv.predict(per_frame),
            content_all.predict(per_frame, fold),
            content_unseen.predict(per_frame, content_unseen.fold_of(take)),
            skating(motion),
            hand_reach(motion),
            hands_up(motion),
            turning(motion),
        )

    def judge(take: str, motion: Motion, fold: int) -> Verdict:
        if take not in judged:
            judged[take] = verdict(motion, fold, take)
            judged_all[take, fold] = judged[take].content_all
        if (take, fold) not in judged_all:
            judged_all[take, fold] = content_all.predict(frame_features(motion), fold)
        return replace(judged[take], content_all=judged_all[take, fold])

    names = ("real held-out", "unchanged", "real target", family,
             f"{family} (pairs with a real target)")  # fmt: skip
    # where the gap is: hand actions (raise, wave) and the rest, with and without a real target
    splits = [f"{w}: {a}" for w in ("real target", f"{family} (pairs)",
              f"{family} (no real target)") for a in ("hand actions", "other actions")]  # fmt: skip
    rows = {k: Tally() for k in (*names, *splits)}
    per_style: dict[str, Tally] = {s: Tally() for s in styles}
    per_style_real: dict[str, Tally] = {s: Tally() for s in styles}
    test = held_list[:limit] if limit else held_list
    for i, x in enumerate(test):
        second = halves(x.motion)[1]
        source = judge(x.take, second, content_all.fold_of(x.take))
        rows["real held-out"].add(source, x.style, x.content, source, x.style, x.take)
        for s in styles:
            real = real_of.get((x.content, s))
            # judged by the folded networks that never saw the real target's take
            fold = content_all.fold_of(real.take if real is not None else f"{x.take}>{s}")
            rows["unchanged"].add(
                judge(x.take, second, fold), s, x.content, source, x.style, x.take
            )
            out = verdict(transfer(family, engine, second, s, strength), fold, x.take)
            rows[family].add(out, s, x.content, source, x.style, x.take)
            per_style[s].add(out, s, x.content, source, x.style, x.take)
            actions = "hand actions" if raises_a_hand(x.content) else "other actions"
            if real is None:
                rows[f"{family} (no real target): {actions}"].add(
                    out, s, x.content, source, x.style, x.take
                )
            else:
                rows[f"{family} (pairs with a real target)"].add(
                    out, s, x.content, source, x.style, x.take
                )
                rows[f"{family} (pairs): {actions}"].add(out, s, x.content, source, x.style, x.take)
                real_verdict = judge(real.take, halves(real.motion)[1], fold)
                rows["real target"].add(real_verdict, s, x.content, source, x.style, x.take)
                rows[f"real target: {actions}"].add(
                    real_verdict, s, x.content, source, x.style, x.take
                )
                per_style_real[s].add(real_verdict, s, x.content, source, x.style, x.take)
        log(
            f"[{family}] {i + 1}/{len(test)} {x.take}: "
            f"{rows[family].summary()} ({time.time() - started:.0f} s)"
        )
    return {
        "family": family,
        "model": f"{entry.name} {entry.version}",
        "model_name": entry.name,
        "model_version": entry.version,
        "strength": strength,
        "held_out_takes": len(test),
        "takes_of": takes_of,
        "takes_unseen_by_family": sum(x.take in own for x in test),
        "styles": len(styles),
        "chance_style": round(1 / len(styles), 4),
        "chance_content": round(1 / len({c.content for c in held_list}), 4),
        "rows": {k: v.summary() for k, v in rows.items()},
        "per_style": {k: v.summary() for k, v in per_style.items()},
        "per_style_real_target": {k: v.summary() for k, v in per_style_real.items()},
        "gaps": gaps(rows, family),
        "seconds": round(time.time() - started, 1),
    }


# (name, row, baseline row, Tally field): the gaps the "Done when" criteria weigh
GAPS = (
    ("style: {f} (pairs) - real target", "{f} (pairs with a real target)", "real target",
     "style"),
    ("content (all takes): {f} (pairs) - real target", "{f} (pairs with a real target)",
     "real target", "content_all"),
    ("content (all takes, merged): {f} (pairs) - real target",
     "{f} (pairs with a real target)", "real target", "content_all_merged"),
    ("content (all takes): {f} - unchanged", "{f}", "unchanged", "content_all"),
    ("content (all takes, merged): {f} - unchanged", "{f}", "unchanged", "content_all_merged"),
    ("content (unseen takes): {f} (pairs) - real target", "{f} (pairs with a real target)",
     "real target", "content_unseen"),
    ("content (unseen takes): {f} - unchanged", "{f}", "unchanged", "content_unseen"),
)  # fmt: skip
GAP_DRAWS = 2000


def gap_interval(
    a: Tally, b: Tally, field_name: str, draws: int = GAP_DRAWS, seed: int = 0
) -> dict | None:
    """Mean of ``a``'s ``field_name`` minus ``b``'s over the same clips (``a`` and ``b``
    hold them in the same order, by take), with a 95% interval from a bootstrap that
    resamples content takes: the clips of one take are not independent (a classifier that
    learnt its first half judges all of them), so resampling clips would understate the
    spread. None where there are no clips."""
    if a.takes != b.takes:
        raise ValueError("gap_interval: the two rows do not hold the same clips in order")
    if not a.takes:
        return None
    diff = np.asarray(getattr(a, field_name), float) - np.asarray(getattr(b, field_name), float)
    takes = sorted(set(a.takes), key=str)
    index = {t: i for i, t in enumerate(takes)}
    which = np.array([index[t] for t in a.takes])
    sums, counts = np.bincount(which, diff, len(takes)), np.bincount(which, None, len(takes))
    picks = np.random.default_rng(seed).integers(0, len(takes), (draws, len(takes)))
    drawn = sums[picks].sum(1) / counts[picks].sum(1)
    low, high = np.percentile(drawn, [2.5, 97.5])
    return {
        "gap": round(float(diff.mean()), 4),
        "low": round(float(low), 4),
        "high": round(float(high), 4),
        "takes": len(takes),
    }


def gaps(rows: dict[str, Tally], family: str) -> dict[str, dict | None]:
    """:data:`GAPS` of ``family``'s rows, each with its interval (:func:`gap_interval`)."""
    return {
        name.format(f=family): gap_interval(rows[a.format(f=family)], rows[b], field_name)
        for name, a, b, field_name in GAPS
    }


def _shown(row: dict, key: str, spec: str) -> str:
    """``row[key]`` formatted by ``spec``; "-" where absent (older reports, rows of no clips)."""
    return "-" if row.get(key) is None else format(row[key], spec)


def markdown(report: dict) -> str:
    lines = [
        f"**{report['family']}** ({report['model']}): {report['held_out_takes']} takes held out "
        f"from the {report['takes_of']}'s training ({report['takes_unseen_by_family']} unseen "
        f"by the {report['family']}) x {report['styles']} styles; chance: style "
        f"{report['chance_style']:.0%}, "
        f"content {report['chance_content']:.0%}"
        + (
            f"; transfers at strength {report['strength']:g}"
            if report.get("strength", 1.0) != 1.0
            else ""
        ),
        "",
        "| output | n | style accuracy | style accuracy (linear) | style read as the content's "
        "| content accuracy | content accuracy (conv) | content accuracy (all takes) "
        "| content accuracy (all takes, merged) | content accuracy (unseen takes) "
        "| foot skating (cm/s) | hand reach (cm, n) | hand use error | turning error (deg) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in report["rows"].items():
        if not row["n"]:
            continue
        skate = _shown(row, "foot_skating_cm_s", ".1f")
        conv = _shown(row, "content_accuracy_conv", ".1%")
        every = _shown(row, "content_accuracy_all_takes", ".1%")
        same = _shown(row, "content_accuracy_all_takes_merged", ".1%")
        unseen = _shown(row, "content_accuracy_unseen_takes", ".1%")
        reach = _shown(row, "hand_reach_cm", "+.1f")
        reach = reach if reach == "-" else f"{reach} ({row['hand_actions']})"
        use, turn = _shown(row, "hand_use_error", ".1%"), _shown(row, "turning_error_deg", ".1f")
        as_source = _shown(row, "style_as_source", ".1%")
        lines.append(
            f"| {name} | {row['n']} | {row['style_accuracy']:.1%} | "
            f"{row['style_accuracy_linear']:.1%} | {as_source} | {row['content_accuracy']:.1%} | "
            f"{conv} | {every} | {same} | {unseen} | {skate} | {reach} | {use} | {turn} |"
        )
    shown_gaps = [(k, g) for k, g in report.get("gaps", {}).items() if g]
    if shown_gaps:
        lines += ["", "Gaps, with 95% intervals (bootstrap over the content takes):", ""]
        lines += [
            f"- {name}: {g['gap']:+.1%} ({g['low']:+.1%} to {g['high']:+.1%}, {g['takes']} takes)"
            for name, g in shown_gaps
        ]
    lines += ["", "Commonest content confusions (all takes), true -> said: count", ""]
    for name, row in report["rows"].items():
        missed = row.get("content_missed_all_takes")
        if row["n"] and missed:
            shown = ", ".join(f"{k}: {v}" for k, v in missed.items())
            lines.append(f"- {name}: {shown}")
    lines += [
        "",
        "| target style | transfers: style accuracy | real target: style accuracy (n) |",
        "|---|---|---|",
    ]
    for style, row in report["per_style"].items():
        real = report.get("per_style_real_target", {}).get(style, {})
        shown = f"{real['style_accuracy']:.0%} ({real['n']})" if real.get("n") else "-"
        lines.append(f"| {style} | {row['style_accuracy']:.0%} | {shown} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("family", choices=(*FAMILIES, "all"))
    p.add_argument("--json", type=Path, default=None, help="write the reports here")
    p.add_argument("--limit", type=int, default=None, help="only the first N held-out takes")
    p.add_argument(
        "--takes",
        choices=FAMILIES,
        default=None,
        help="judge on this family's held-out takes (default: each family's own); the "
        "side-by-side comparison judges both on the same takes",
    )
    p.add_argument(
        "--no-mirror",
        action="store_true",
        help="train the style classifier without the mirror images of the held-out takes",
    )
    p.add_argument(
        "--classifier-cache",
        type=Path,
        default=None,
        help="keep the trained classifiers in this folder and use them again while the "
        "takes and the code that makes the classifiers are the same",
    )
    p.add_argument(
        "--manifest",
        action="store_true",
        help="also record each report's figures in the model's manifest entry "
        "(metrics.evaluation.<takes>_held_out_takes), so they travel with the model",
    )
    p.add_argument(
        "--strength",
        type=float,
        default=1.0,
        help="the translator's transfers at this strength, 0 to 1 (the API's; default 1)",
    )
    args = p.parse_args(argv)
    families = FAMILIES if args.family == "all" else (args.family,)
    for f in families:
        try:
            check_strength(f, args.strength)
        except ValueError as e:
            p.error(f"--strength: {e}")
    if args.strength != 1.0 and args.manifest:
        p.error("--manifest records the figures at full strength, as the API's default")
    reports = [
        evaluate(
            f, args.takes, args.limit, mirror=not args.no_mirror,
            classifier_cache=args.classifier_cache, strength=args.strength,
        )
        for f in families
    ]  # fmt: skip
    for r in reports:
        print()
        print(markdown(r))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(reports, indent=1))
    if args.manifest:
        from service.config import Settings

        for r in reports:
            record_in_manifest(r, Settings().models_dir)
    return 0


def record_in_manifest(report: dict, models_dir: Path) -> None:
    """The report's table (rows, takes, date) into its model's entry in ``models_dir``."""
    from model_export.manifest import measuring_machine, put_evaluation

    figures = {
        "held_out_takes": report["held_out_takes"],
        "styles": report["styles"],
        "rows": report["rows"],
        "gaps": report.get("gaps"),
        "measured": time.strftime("%Y-%m-%d"),
        "machine": measuring_machine(),
        "by": "python -m training.eval_style (style, content_conv: convolutional classifiers; "
        "content_all_takes: the same trained on the training takes too, in folds by take; "
        "content_unseen_takes: the held-out takes folded too, each clip judged by networks "
        "that never saw the take its motion comes from; "
        "style_linear, content: logistic regression; foot skating in cm/s; hand reach: cm "
        "above the head over clips of hand actions)",
    }
    put_evaluation(
        report["model_name"],
        report["model_version"],
        f"{report['takes_of']}_held_out_takes",
        figures,
        models_dir,
    )


if __name__ == "__main__":
    # run as the imported module: classifiers pickled by ``python -m`` would otherwise name
    # their classes ``__main__.*`` and load nowhere else (a script or a test importing this)
    from training import eval_style

    raise SystemExit(eval_style.main())

"""Training the translator (aberman2020 section 3.2-3.3): ``python -m training.translator``.

One step, for a batch of B content windows ``m`` (style s):

- ``n``: a window of style s (with probability ``p_self`` m itself): the content
  consistency loss asks ``F(E_C(m) | E_S(n)) == m``, L1 on standardised rotations and on
  FK positions (paper eq. 3).
- with ``w_rec_vel``: L1 on the joint velocities of that reconstruction too (not in the
  paper): positions alone left the decoder's output jittery, its round trip's joint
  velocities off by 28.9 cm/s on held-out windows (0.1.89894; joints of training windows
  move at 39.7 cm/s on average), and a wave is told from a held raise by how the hand moves.
- ``x``: a window of another style t: ``F(E_C(m) | E_S(x))`` must look like style t to
  the multi-style discriminator (hinge loss, only output t counts; eq. 4) and match the
  mean discriminator features of real style-t windows in the batch (eq. 5). With
  ``pair_content``, t is a style that performs m's content label (Bandai's content: walk,
  wave-left-hand...) where another style does, and x a window of that content: the
  discriminator then compares a translation with real style-t motion of the same action.
  Drawn at random, the discriminator of a style whose takes never raise a hand judges
  raised hands, and the translator lowers them for such styles.
- with ``w_cycle``: the content encoder must give back m's content code from a
  translation of m to a window r of any other style (x unless ``pair_content``; not in
  the paper): it asks every translation to keep what m performs, also to styles whose
  takes never perform it, which no other term judges.
- with ``w_raised_hands``: where m holds a hand above its head, the translation of m to r
  must too (``hands_dropped``; not in the paper), r then a style whose takes never
  perform m's content (with ``pair_content``): its style may change how the hand rises,
  not whether it ends above the head. Styles that do perform it (feminine raises hands
  lower than most) are left to the discriminator, which compares them with their takes.
- with ``w_lifted_hands``: where m holds a hand well below its head, the translations to x
  (and r) must not lift it above the head (``hands_lifted``; not in the paper): translations
  of wave-left-hand to the styles that never wave raised both hands.
- with ``w_hand_amplitude``: each hand of the translations to x (and r) moves within a
  factor of two as much as in m (``hand_amplitude_changed``; not in the paper): they had
  swung the idle hand of one-hand actions and shrunk the raised one, and the content
  classifier took raises for waves.
- with ``w_hand_speed``: the same for each hand's mean speed (``hand_speed_changed``; not
  in the paper): a wave keeps the hand moving where a raise holds it.
- with ``w_foot_pitch``: where m has a foot flat on the floor (heel and toe planted), the
  translations to x (and r) pitch it as m does (``feet_pitched``; not in the paper): the
  decoder pitched feet toe-down, so planted toes sank under the content's floor and the
  clean-up could not hold them on it without swing toes skimming it.
- with ``w_content_adv``: the discriminator also has a head per content label (``walk``,
  ``raise-up-left-hand``...), trained like the style heads on real windows of that label
  (any style) against translations of content windows with that label (to x, and to r);
  the translations to x (and r) must pass the head of m's label (not in the paper). The
  style heads judge style but not what is performed, and translations of raises passed as
  waves.
- with ``w_style_cls``: the style heads' scores, averaged over time, are also logits of a
  19-way style classifier: the discriminator learns to classify real m and x windows by
  their style (cross-entropy), and the translation to x must be classified as x's style
  (StarGAN's domain classification, with the classifier trained on reals only; not in the
  paper). The hinge heads ask only whether a window is a real one of style t, not whether
  it is more t than any other style, which is what a style classifier judges.
- with ``w_content_style``: a linear probe learns m's style from the time mean and deviation
  of its content code (its own optimizer, on detached codes), and the content encoder must
  make the probe's answer the styles that perform m's content label, in their share of the
  training frames (not in the paper). Instance norm was meant to strip style from the content
  code, but such a probe trained on the training takes named the style of 82% of held-out
  windows from 0.1.71412's codes (chance 5%), and transfers kept their source style:
  18% of the transfers with a real target were classified as the content clip's style,
  against 9% of those real targets. Measured, 6,525 steps from 0.1.71412 (weight 1, then 2
  with ``probe_lr`` 1e-2): the held-out probe fell to 72-78%, transfers read as their source
  style to 15%, but style recognition did not rise (44.0 -> 43.9% where a real target
  exists) and content fell 66.6 -> 61.5%: not in the shipped schedule.
- with ``w_paired`` (and ``pair_content``): the translation to x must match x's own clip, a
  real performance of m's content label in x's style, at the frames dynamic time warping
  aligns with m's window (``TD.Alignments``; L1 of the body relative to the hips, as the
  decoder sets no hips height; not in the paper). Bandai performs each action in up to 19
  styles: the adversarial terms only say a translation looks like style t, these pairs
  show what m's action looks like performed in it. Measured from 0.1.96598: at weights 50
  and 150, 1,200-7,650 steps, content of all transfers +2.9 to +5.7 points and of unseen
  takes +1.1 to +4.7, style where a real target exists -1.3 to +0.4 (weights 2 and 8:
  noise). Shipped as 0.1.100410.
  With ``w_paired_vel``, each joint's displacement over ``paired_vel_frames`` (relative to
  the hips) is compared as well, a term that leaves the style its posture: from 0.1.100410
  at weight 50 beside ``w_paired`` 50, content -1.5 to -2.5 points, not kept.
- with ``w_wild_motion``: the translation to r, a style that never performs m's content
  (no real target), moves each joint as m does over ``paired_vel_frames`` (hips-relative),
  posture left free (not in the paper). From 0.1.100410 at weight 100: content of all
  transfers +3.2 to +4.1 points after 5,000-7,500 steps, of unseen takes +1.4 to +1.8,
  style where a real target exists -0.6 to -0.2. Shipped as 0.1.105388.
- 2D views of n and x go through the 2D style encoder: joint embedding loss (eq. 6); the
  decoder is fed the 3D or the 2D code (chosen per sample), so it learns to use both.
- triplet loss on 3D codes (eq. 7): ``|z(n) - z(m)|`` shorter than ``|z(n) - z(x)|`` by a margin.

The discriminator reads real m and x windows and the detached translations, with a lazy
R1 penalty on reals. The adversarial and feature-matching weights ramp up over
``adv_warmup`` steps: from the start they held reconstruction back (measured: L1 of
rotations 0.67 vs 0.52 after 200 steps).

Checkpoints (one file, overwritten, resumable) hold both networks, optimizers, step,
configs, statistics and the validation takes; the statistics (``*_stats.npz``) and the
run's config (``*_config.json``) are also written beside it. ``MOTION_SMOKE=1`` or
``--max-steps`` stops early (smoke tests). A validation reconstruction error over
``diverged_factor`` times the run's best stops the run before it overwrites the checkpoint:
two fine-tuning runs of a grown decoder collapsed after 3,000 and 6,000 steps (the
generator drove the content heads' scores without bound, before those heads learned from
translations to r, and reconstruction went from 3 to 15-22 cm).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from motion import canonical as C
from motion import contacts as Ct
from motion import features as Fe
from training import data as D
from training.fk import RootLocalFK
from training.translator import data as TD
from training.translator.model import (
    AMPLITUDE_PARAMETERS,
    STRIDE,
    Discriminator,
    MixedConv,
    ModelConfig,
    Translator,
    calibrate_amplitude,
    count_parameters,
)

REPO = Path(__file__).resolve().parents[2]
DEFAULT_CHECKPOINT = REPO / "checkpoints" / "translator.pt"
DEFAULT_LOG_DIR = REPO / "runs" / "translator"
CALIBRATION_WINDOWS = 256


@dataclass
class TrainConfig:
    """Schedule, loss weights and data choices of a run (saved with the weights)."""

    steps: int = 50000
    batch_size: int = 32
    window: int = 32
    lr: float = 2e-4
    lr_final_fraction: float = 0.1  # cosine decay to lr * this at ``steps``
    views: int = 8  # 2D projections per clip in the bank
    p_self: float = 0.25
    # the other style's window performs the content window's label where that style has it
    pair_content: bool = False
    p_style2d: float = 0.3
    w_rec_rot: float = 1.0
    w_rec_pos: float = 10.0  # positions are in leg lengths: errors of ~0.05
    # L1 of the reconstruction's joint velocities (root-local, leg lengths a frame)
    w_rec_vel: float = 0.0
    w_adv: float = 0.5
    w_fm: float = 0.5
    adv_warmup: int = 4000  # adversarial and feature-matching weights ramp up over these steps
    w_joint: float = 0.3
    w_trip: float = 0.3
    # content cycle: E_C of a translation must give back the content code it was decoded from
    w_cycle: float = 0.0
    # a hand the content window raises above the head stays above it in a translation to r
    w_raised_hands: float = 0.0
    # a hand the content window holds well below the head stays below it, in the
    # translations to x (and r)
    w_lifted_hands: float = 0.0
    # each hand moves within a factor hand_amplitude_ratio as much as in the content window,
    # in the translations to x (and r)
    w_hand_amplitude: float = 0.0
    hand_amplitude_ratio: float = 2.0
    # each hand's mean speed within a factor hand_speed_ratio of the content window's, in
    # the same translations
    w_hand_speed: float = 0.0
    hand_speed_ratio: float = 1.5
    # the discriminator's content heads judge whether a translation performs m's label
    w_content_adv: float = 0.0
    # a foot the content window has flat on the floor is pitched as in the content
    w_foot_pitch: float = 0.0
    # the style heads also classify: real windows by their style, the translation to x as x's
    w_style_cls: float = 0.0
    # the content code must not tell a linear probe more of m's style than its content label
    w_content_style: float = 0.0
    # with pair_content: the translation to x matches x's clip, a real performance of m's
    # content label in x's style, aligned to m by dynamic time warping (body relative to
    # the hips)
    w_paired: float = 0.0
    # the same pairs' motion: hips-relative displacements over paired_vel_frames, which
    # leave the style its own posture
    w_paired_vel: float = 0.0
    paired_vel_frames: int = 4
    # translations to a style that never performs m's content have no real target: they
    # move each joint as m does (hips-relative, over paired_vel_frames), posture left free
    w_wild_motion: float = 0.0
    # translations stand on the content's floor, as the service grounds them
    # (:func:`ground_translation`), not at the content's hips height
    ground_translations: bool = False
    grounding_frames: float = 15.0  # Gaussian sigma of the hips' shift (the service's 0.5 s)
    probe_lr: float = 1e-3
    content_head_lr_scale: float = 10.0  # a head added to a trained discriminator catches up
    amplitude_lr_scale: float = 10.0  # the same for what keep_amplitude adds to a generator
    triplet_margin: float = 5.0
    w_r1: float = 1.0
    r1_every: int = 4
    val_fraction: float = 0.12
    seed: int = 0
    val_every: int = 500
    val_windows: int = 512
    checkpoint_minutes: float = 10.0
    # validation rec_pos_cm over this many times the run's best (after adv_warmup; a resumed
    # run starts from its checkpoint's): the generator has found a way past a discriminator
    # head and is drifting off the data, so stop and keep the last checkpoint
    diverged_factor: float = 1.5
    clips_per_style: int = 0  # > 0: a tiny subset, for smoke tests
    # the training clips also performed with left and right swapped (a style has no side);
    # validation stays as recorded
    mirror: bool = False
    # windows a step of motion outside Bandai (CMU, Xia, Dance with Melody), reconstructed
    # with their own style code under the reconstruction weights: the encoder and decoder
    # see more than the 399 training takes they fit within 1 cm (held-out takes: 3 cm)
    extra_batch: int = 0
    datasets: tuple[int, ...] = (1, 2)


# --------------------------------------------------------------------------- data


@dataclass
class Prepared:
    styles: list[str]
    contents: list[str]  # content labels of the training takes, sorted
    train: list[TD.EncodedClip]
    val: list[TD.EncodedClip]
    val_takes: list[str]
    stats: Fe.FeatureStats
    extra: list[TD.EncodedClip] = dataclasses.field(default_factory=list)  # unlabelled motion


def prepare(cfg: TrainConfig, val_takes: list[str] | None = None) -> Prepared:
    """Load Bandai, split by take (or by the given validation takes), encode, statistics."""
    clips = D.load_bandai(datasets=tuple(cfg.datasets))
    if cfg.clips_per_style > 0:
        per: dict[str, list] = {}
        for c in sorted(clips, key=lambda c: c.take):
            if c.num_frames >= cfg.window:
                per.setdefault(c.style, []).append(c)
        clips = [c for cs in per.values() for c in cs[: cfg.clips_per_style]]
    styles = sorted({c.style for c in clips})
    if val_takes is None:
        train, val = D.split_by_take(clips, cfg.val_fraction, cfg.seed, stratify="style")
        val_takes = sorted({c.take for c in val})
    else:
        chosen = set(val_takes)
        train = [c for c in clips if c.take not in chosen]
        val = [c for c in clips if c.take in chosen]
    if cfg.mirror:
        train = train + [TD.mirrored_clip(c) for c in train]
    enc_train = TD.encode_clips(train, styles, cfg.window, cfg.views, cfg.seed)
    enc_val = TD.encode_clips(val, styles, cfg.window, 1, cfg.seed + 1)
    stats = Fe.compute_stats(
        {
            "content": [c.content for c in enc_train],
            "style3d": [c.style3d for c in enc_train],
            "style2d": [v for c in enc_train for v in c.style2d],
        }
    )
    contents = sorted({c.label for c in enc_train if c.label is not None})
    extra = []
    if cfg.extra_batch > 0:  # left out of the statistics: the model is Bandai's
        extra = TD.encode_clips(D.load_unlabelled_motion(), styles, cfg.window, 1, cfg.seed + 2)
    return Prepared(styles, contents, enc_train, enc_val, val_takes, stats, extra)


class ChannelStats(torch.nn.Module):
    """One kind's statistics as tensors; ``(B, C, T)`` in and out."""

    def __init__(self, mean: np.ndarray, std: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("mean", torch.tensor(mean)[None, :, None])
        self.register_buffer("std", torch.tensor(std)[None, :, None])

    def standardize(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std

    def unstandardize(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.std + self.mean


class Standardizer(torch.nn.Module):
    """``motion.features`` statistics for torch: ``content``, ``style3d``, ``style2d``,
    ``output`` (each a :class:`ChannelStats`)."""

    def __init__(self, stats: Fe.FeatureStats) -> None:
        super().__init__()
        self.content = ChannelStats(*stats.get("content"))
        self.style3d = ChannelStats(*stats.get("style3d"))
        self.style2d = ChannelStats(*stats.get("style2d"))
        self.output = ChannelStats(*stats.get("output"))


@dataclass
class Batch:
    """Standardised tensors ``(B, C, T)`` of one kind of window, plus raw helpers."""

    content: torch.Tensor
    style3d: torch.Tensor
    style2d: torch.Tensor
    style: torch.Tensor  # (B,)
    positions: torch.Tensor  # (B, T, 21, 3) raw root-local positions, leg lengths
    hips_height: torch.Tensor  # (B, T) leg lengths
    label: torch.Tensor | None = None  # (B,) content label index, -1 for none

    @property
    def rotations(self) -> torch.Tensor:
        return self.content[:, : Fe.OUTPUT_CHANNELS]

    @property
    def disc_input(self) -> torch.Tensor:
        return torch.cat([self.style3d, self.rotations], dim=1)


def to_batch(w: TD.Windows, norm: Standardizer) -> Batch:
    def t(x: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 2, 1)))

    content = t(w.content)
    return Batch(
        content=norm.content.standardize(content),
        style3d=norm.style3d.standardize(t(w.style3d)),
        style2d=norm.style2d.standardize(t(w.style2d)),
        style=torch.from_numpy(w.style).long(),
        positions=torch.from_numpy(w.style3d).reshape(w.style3d.shape[:2] + (-1, 3)),
        hips_height=content[:, Fe.ROTATION_CHANNELS],
    )


# --------------------------------------------------------------------------- losses


_FEET = [j - 1 for j in Ct.CANONICAL_FOOT_JOINTS]  # body joints: joint_Root left out


def ground_translation(
    content: torch.Tensor, translation: torch.Tensor, sigma_frames: float
) -> torch.Tensor:
    """``translation`` raised or lowered, slowly, so that the lowest of its foot joints
    that the content plants stands on the content's ground level of that joint: the
    torch twin of ``motion.ik.ground_hips``, which the service applies after decoding.
    Root-local positions ``(B, T, 21, 3)`` in leg lengths. Contacts here are by height
    alone (within ``HEIGHT_FRACTION`` of the joint's lowest in the window): root-local
    positions carry no horizontal speed. A foot the content holds up through the whole
    window is left out, as the service's ground levels leave it out. Without it the
    discriminator judged translations at the content's hips height, legs sunk into the
    floor or floating, which no inference output shows."""
    level, planted = _ground_contacts(content)
    gap = level - translation[..., _FEET, 1]
    lowest = torch.where(planted, gap, torch.full_like(gap, -torch.inf)).amax(dim=-1)
    held = planted.any(dim=-1)
    weight = held.to(translation.dtype)
    lowest = torch.where(held, lowest, torch.zeros_like(lowest))
    # Gaussian smoothing of the held frames' shifts, normalised by the held weight, so
    # frames without contact take their neighbours' shift (the service interpolates)
    radius = max(1, int(math.ceil(3 * sigma_frames)))
    t = torch.arange(-radius, radius + 1, dtype=translation.dtype)
    kernel = torch.exp(-0.5 * (t / sigma_frames) ** 2)[None, None]
    num = F.conv1d((lowest * weight)[:, None], kernel, padding=radius)[:, 0]
    den = F.conv1d(weight[:, None], kernel, padding=radius)[:, 0]
    shift = torch.where(den > 1e-6, num / den.clamp_min(1e-6), torch.zeros_like(den))
    up = torch.zeros(3, dtype=translation.dtype)
    up[1] = 1.0
    return translation + shift[..., None, None] * up


def _ground_contacts(content: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each foot joint's (:data:`_FEET`) ground level in the window ``(B, 1, 4)`` and
    whether the content plants it ``(B, T, 4)``, by height alone."""
    feet = content[..., _FEET, 1]
    level = feet.amin(dim=1, keepdim=True)
    level = torch.minimum(level, level.amin(dim=-1, keepdim=True) + Ct.MAX_GROUND_ELEVATION)
    return level, feet - level < Ct.HEIGHT_FRACTION


def feet_pitched(content: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """Mean difference of the ankle-to-toe rise between translation and content over the
    frames where the content has that foot flat (heel and toe planted), in leg lengths (0
    where it never has). Root-local positions ``(B, T, 21, 3)``."""
    _, planted = _ground_contacts(content)
    flat = planted[..., 0::2] & planted[..., 1::2]  # (B, T, 2): each foot's ankle and toe

    def rise(p: torch.Tensor) -> torch.Tensor:
        y = p[..., _FEET, 1]
        return y[..., 1::2] - y[..., 0::2]

    error = (rise(translation) - rise(content)).abs()
    return (error * flat).sum() / flat.sum().clamp_min(1)


_HANDS = [C.INDEX["Hand_L"] - 1, C.INDEX["Hand_R"] - 1]  # body joints: joint_Root left out
_HEAD = C.INDEX["Head"] - 1


def hands_dropped(content: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """Mean depth below the head of the translation's hands, over the frames where the
    content holds that hand above its head (leg lengths; 0 where it never does). Root-local
    positions ``(B, T, 21, 3)``. Twelve Bandai styles never raise a hand, and translations
    to them lowered raised hands by 30-46 cm: the style may change how a hand is raised,
    not whether it ends above the head."""
    above = content[..., _HANDS, 1] - content[..., [_HEAD], 1]
    height = translation[..., _HANDS, 1] - translation[..., [_HEAD], 1]
    raised = (above > 0).float()
    return (F.relu(-height) * raised).sum() / raised.sum().clamp_min(1.0)


_LOWERED = 10.0 / Fe.LEG  # 10 cm below the head: a hand clearly down, not a hand near the face


def hands_lifted(content: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """Mean height above the head of the translation's hands, over the frames where the
    content holds that hand more than 10 cm below its head (leg lengths); the converse of
    :func:`hands_dropped`. Translations of wave-left-hand to the styles that never wave
    (0.1.53000) held the idle right hand above the head in 94% of frames, the content in
    none, and the content classifier read them as waves of both hands. Measured, 3,000 steps
    with weight 2 from 0.1.53000 (0.1.56000): the fraction of frames each hand of
    a transferred raise or wave is above the head is 0.169 off the content's (0.211 before;
    real performances in the target style: 0.237), style 28.6 -> 28.9%, content of all
    transfers 53.0 -> 52.8% (all-takes classifier)."""
    below = content[..., _HANDS, 1] - content[..., [_HEAD], 1] < -_LOWERED
    height = translation[..., _HANDS, 1] - translation[..., [_HEAD], 1]
    lowered = below.float()
    return (F.relu(height) * lowered).sum() / lowered.sum().clamp_min(1.0)


_AMPLITUDE_FLOOR = 2.0 / Fe.LEG  # 2 cm: a hand at rest jitters; below this it is still


def hand_amplitude_changed(
    content: torch.Tensor, translation: torch.Tensor, ratio: float
) -> torch.Tensor:
    """How far (log ratio) each hand's amplitude of movement in the translation is from the
    content's, beyond a factor ``ratio`` either way; mean over hands.
    Amplitude: root-local position's standard deviation over the window (``(B, T, 21, 3)``,
    leg lengths). Instance norm strips it from the content code, and translations of
    one-hand actions moved the idle hand 3-5x as fast as the content while the raised
    hand's height varied 60% less (real takes, by style: 14-30 cm over a clip)."""

    def amplitude(p: torch.Tensor) -> torch.Tensor:
        hands = p[..., _HANDS, :]
        return hands.var(dim=1, unbiased=False).sum(-1).sqrt() + _AMPLITUDE_FLOOR

    return _beyond(amplitude(translation) / amplitude(content), ratio)


_SPEED_FLOOR = 3.0 / Fe.FPS / Fe.LEG  # 3 cm/s, per frame


def hand_speed_changed(
    content: torch.Tensor, translation: torch.Tensor, ratio: float
) -> torch.Tensor:
    """As :func:`hand_amplitude_changed`, for each hand's mean speed over the window. A raise
    and a wave move a hand as far, but a wave keeps it moving: the content classifier took
    translated raises for waves and waves for raises (47 of the 140 transfers of hand
    actions to styles that perform them, in 0.1.50000; 16 of the real takes of those
    actions in those styles). Measured, 3,000 steps with weight 4 from 0.1.53000: content
    of all transfers 53.0 -> 51.9% (all-takes classifier), of hand actions with a real
    target 55.0 -> 52.9%: not in the shipped schedule."""

    def speed(p: torch.Tensor) -> torch.Tensor:
        hands = p[..., _HANDS, :]
        return (hands[:, 1:] - hands[:, :-1]).norm(dim=-1).mean(dim=1) + _SPEED_FLOOR

    return _beyond(speed(translation) / speed(content), ratio)


def hips_relative_l1(positions: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L1 between two ``(B, T, 21, 3)`` root-local poses relative to their hips (body joint
    0): the decoder sets no hips height, a real performance of another style has its own."""
    return F.l1_loss(_relative_to_hips(positions), _relative_to_hips(target))


def _relative_to_hips(positions: torch.Tensor) -> torch.Tensor:
    return positions - positions[..., :1, :]


def hips_relative_motion_l1(
    positions: torch.Tensor, target: torch.Tensor, frames: int
) -> torch.Tensor:
    """L1 between how far each joint of two ``(B, T, 21, 3)`` root-local poses moves,
    relative to the hips, over ``frames`` frames: the action's motion without the posture,
    which a style may change. Over a few frames, not one, because time warping repeats and
    skips frames of the target."""
    rel, ref = _relative_to_hips(positions), _relative_to_hips(target)
    return F.l1_loss(rel[:, frames:] - rel[:, :-frames], ref[:, frames:] - ref[:, :-frames])


def _beyond(ratios: torch.Tensor, ratio: float) -> torch.Tensor:
    """Mean of how far (log) ``ratios`` fall outside ``[1 / ratio, ratio]``."""
    return F.relu(torch.log(ratios).abs() - math.log(ratio)).mean()


class Losses:
    """The networks and the loss terms of one step; ``generator`` and ``discriminator``."""

    def __init__(
        self,
        g: Translator,
        d: Discriminator,
        norm: Standardizer,
        cfg: TrainConfig,
        probe: torch.nn.Linear | None = None,
        style_prior: torch.Tensor | None = None,
    ):
        """``probe`` and ``style_prior`` (content labels x styles, rows summing to 1) for
        ``w_content_style``."""
        self.g, self.d, self.norm, self.cfg = g, d, norm, cfg
        self.probe, self.style_prior = probe, style_prior
        self.fk = RootLocalFK()

    def positions(self, output: torch.Tensor, hips_height: torch.Tensor) -> torch.Tensor:
        """Root-local positions ``(B, T, 21, 3)`` of standardised output ``(B, 126, T)``."""
        raw = self.norm.output.unstandardize(output).transpose(1, 2)
        return self.fk(raw.reshape(raw.shape[:2] + (-1, 6)), hips_height)

    def translated_positions(self, output: torch.Tensor, m: Batch) -> torch.Tensor:
        """Positions of a translation of content ``m``, grounded on m's floor if the run
        asks for it."""
        pos = self.positions(output, m.hips_height)
        if self.cfg.ground_translations:
            pos = ground_translation(m.positions, pos, self.cfg.grounding_frames)
        return pos

    def disc_input(self, output: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        flat = positions.reshape(positions.shape[:2] + (-1,)).transpose(1, 2)
        return torch.cat([self.norm.style3d.standardize(flat), output], dim=1)

    def style_codes(self, b: Batch, use2d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """3D code and the code fed to the decoder (2D where ``use2d``), ``(B, S)``."""
        z3 = self.g.style3d(b.style3d)
        z2 = self.g.style2d(b.style2d)
        return z3, torch.where(use2d[:, None], z2, z3), z2

    @staticmethod
    def pick(scores: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """The given style's scores ``(B, T')`` of ``(B, S, T')``."""
        return scores[torch.arange(len(style)), style]

    def pick_content(self, scores: torch.Tensor, label: torch.Tensor | None) -> torch.Tensor:
        """Each window's content-head scores ``(B', T')``, windows without a label left out
        (empty without content heads)."""
        if label is None or self.d.content_head is None:
            return scores.new_zeros((0, scores.shape[-1]))
        keep = label >= 0
        return self.pick(scores[keep], self.g.cfg.num_styles + label[keep])

    def style_logits(self, scores: torch.Tensor) -> torch.Tensor:
        """The style heads' scores ``(B, S + contents, T')`` averaged over time: ``(B, S)``."""
        return scores[:, : self.g.cfg.num_styles].mean(dim=-1)

    @staticmethod
    def hinge_mean(x: torch.Tensor) -> torch.Tensor:
        return x.mean() if x.numel() else x.new_zeros(())

    def reconstruction(
        self, m: Batch, z_content: torch.Tensor, code: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """L1 of m decoded from its content code with ``code``: standardised rotations,
        root-local positions and their velocities (zero unless ``w_rec_vel``)."""
        rec = self.g.decoder(z_content, code)
        rot = F.l1_loss(rec, m.rotations)
        positions = self.positions(rec, m.hips_height)
        pos = F.l1_loss(positions, m.positions)
        vel = torch.zeros(())
        if self.cfg.w_rec_vel > 0:
            vel = F.l1_loss(positions.diff(dim=1), m.positions.diff(dim=1))
        return rot, pos, vel

    def generator(
        self,
        m: Batch,
        n: Batch,
        x: Batch,
        ramp: float = 1.0,
        r: Batch | None = None,
        e: Batch | None = None,
        paired: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> tuple[torch.Tensor, dict, torch.Tensor, torch.Tensor | None]:
        """Generator loss, its parts, and the discriminator inputs (detached) of the
        translations to x and to ``r`` (None where no term translates to r), so that the
        discriminator does not run forward kinematics on them again; ``ramp`` in [0, 1]
        scales the adversarial terms (they slow reconstruction down early on); the content
        cycle translates m to ``r``'s style (default x); ``e``, unlabelled windows, adds
        their reconstruction with their own codes."""
        cfg = self.cfg
        use2d = torch.rand(len(m.style)) < cfg.p_style2d
        z_content = self.g.content_encoder(m.content)
        z3_n, code_n, z2_n = self.style_codes(n, use2d)
        z3_x, code_x, z2_x = self.style_codes(x, torch.roll(use2d, 1))
        z3_m = self.g.style3d(m.style3d)

        rec_rot, rec_pos, rec_vel = self.reconstruction(m, z_content, code_n)
        extra_rec = extra_pos = torch.zeros(())
        if e is not None:
            parts = self.reconstruction(
                e, self.g.content_encoder(e.content), self.g.style3d(e.style3d)
            )
            extra_rec = (
                cfg.w_rec_rot * parts[0] + cfg.w_rec_pos * parts[1] + cfg.w_rec_vel * parts[2]
            )
            extra_pos = parts[1]

        fake = self.g.decoder(z_content, code_x)
        fake_pos = self.translated_positions(fake, m)
        fake_in = self.disc_input(fake, fake_pos)
        scores, feats = self.d(fake_in)
        adv = -self.pick(scores, x.style).mean()
        with torch.no_grad():
            real_feats = self.d(x.disc_input)[1].mean(dim=-1)
            onehot = F.one_hot(x.style, self.g.cfg.num_styles).float()
            per_style = onehot.T @ real_feats / onehot.sum(0).clamp_min(1)[:, None]
            target = per_style[x.style]
        fm = F.l1_loss(feats.mean(dim=-1), target)
        style_cls = torch.zeros(())
        if cfg.w_style_cls > 0:
            style_cls = F.cross_entropy(self.style_logits(scores), x.style)

        cycle, raised, lifted, amplitude, speed, pitch = (torch.zeros(()) for _ in range(6))
        paired_err = paired_motion = torch.zeros(())
        if paired is not None and bool(paired[1].any()):
            fake_paired, target_paired = fake_pos[paired[1]], paired[0][paired[1]]
            paired_err = hips_relative_l1(fake_paired, target_paired)
            if cfg.w_paired_vel > 0:
                paired_motion = hips_relative_motion_l1(
                    fake_paired, target_paired, cfg.paired_vel_frames
                )
        content_adv = torch.zeros(())
        wild = wild_pos = wild_in = None
        if cfg.w_cycle > 0 or cfg.w_raised_hands > 0:
            # to r, a style that may not perform m's content: no other term judges those
            # translations
            r = x if r is None else r
            wild = fake if r is x else self.g.decoder(z_content, self.g.style3d(r.style3d))
            if wild is fake:
                wild_pos = fake_pos
            else:  # the discriminator's content heads learn from it as a fake
                wild_pos = self.translated_positions(wild, m)
                wild_in = self.disc_input(wild, wild_pos)
        if cfg.w_cycle > 0:
            root = m.content[:, Fe.OUTPUT_CHANNELS :]
            again = self.g.content_encoder(torch.cat([wild, root], dim=1))
            cycle = F.l1_loss(again, z_content.detach())
        if cfg.w_raised_hands > 0:
            raised = hands_dropped(m.positions, wild_pos)
        wild_motion = torch.zeros(())
        if cfg.w_wild_motion > 0 and wild_in is not None:
            wild_motion = hips_relative_motion_l1(wild_pos, m.positions, cfg.paired_vel_frames)

        def on_translations(term, *args) -> torch.Tensor:
            """``term`` of the translation to x, averaged with the one to r if there is one."""
            value = term(m.positions, fake_pos, *args)
            if wild_in is not None:
                value = 0.5 * (value + term(m.positions, wild_pos, *args))
            return value

        if cfg.w_lifted_hands > 0:
            lifted = on_translations(hands_lifted)

        if cfg.w_hand_amplitude > 0:
            amplitude = on_translations(hand_amplitude_changed, cfg.hand_amplitude_ratio)
        if cfg.w_hand_speed > 0:
            speed = on_translations(hand_speed_changed, cfg.hand_speed_ratio)
        if cfg.w_foot_pitch > 0:
            pitch = on_translations(feet_pitched)
        if cfg.w_content_adv > 0:
            content_adv = -self.hinge_mean(self.pick_content(scores, m.label))
            if wild_in is not None:
                wild_scores = self.d(wild_in)[0]
                wild_adv = -self.hinge_mean(self.pick_content(wild_scores, m.label))
                content_adv = 0.5 * (content_adv + wild_adv)

        content_style = probe_ce = probe_acc = torch.zeros(())
        if cfg.w_content_style > 0:
            content_style, probe_ce, probe_acc = self.content_style(z_content, m)

        joint = 0.5 * (F.mse_loss(z2_n, z3_n) + F.mse_loss(z2_x, z3_x))
        d_pos = (z3_n - z3_m).norm(dim=-1)
        d_neg = (z3_n - z3_x).norm(dim=-1)
        trip = F.relu(d_pos - d_neg + cfg.triplet_margin).mean()

        total = (
            cfg.w_rec_rot * rec_rot
            + cfg.w_rec_pos * rec_pos
            + cfg.w_rec_vel * rec_vel
            + extra_rec
            + ramp * cfg.w_adv * adv
            + ramp * cfg.w_fm * fm
            + cfg.w_joint * joint
            + cfg.w_trip * trip
            + cfg.w_cycle * cycle
            + cfg.w_raised_hands * raised
            + cfg.w_lifted_hands * lifted
            + cfg.w_hand_amplitude * amplitude
            + cfg.w_hand_speed * speed
            + cfg.w_foot_pitch * pitch
            + ramp * cfg.w_content_adv * content_adv
            + ramp * cfg.w_style_cls * style_cls
            + ramp * cfg.w_content_style * content_style
            + cfg.w_paired * paired_err
            + cfg.w_paired_vel * paired_motion
            + cfg.w_wild_motion * wild_motion
        )
        logs = {
            "rec_rot": rec_rot, "rec_pos_cm": rec_pos * Fe.LEG,
            "rec_vel_cm_s": rec_vel * Fe.LEG * C.FPS, "extra_rec_pos_cm": extra_pos * Fe.LEG,
            "adv_g": adv, "feature_match": fm,
            "joint": joint, "triplet": trip, "content_cycle": cycle,
            "raised_hands_cm": raised * Fe.LEG, "lifted_hands_cm": lifted * Fe.LEG,
            "hand_amplitude": amplitude, "hand_speed": speed, "foot_pitch_cm": pitch * Fe.LEG,
            "content_adv_g": content_adv, "style_cls_g": style_cls,
            "content_style_kl": content_style, "probe_ce": probe_ce, "probe_acc": probe_acc,
            "paired_cm": paired_err * Fe.LEG, "paired_motion_cm": paired_motion * Fe.LEG,
            "wild_motion_cm": wild_motion * Fe.LEG,
            "total_g": total,
        }  # fmt: skip
        total = total + probe_ce  # reaches only the probe, which has its own optimizer
        wild_in = None if wild_in is None else wild_in.detach()
        return total, {k: float(v.detach()) for k, v in logs.items()}, fake_in.detach(), wild_in

    def content_style(self, z: torch.Tensor, m: Batch) -> tuple:
        """KL from the style prior of m's content labels to the probe's answer on the
        content codes ``z`` (gradient to the encoder only), the probe's cross-entropy on the
        detached codes (gradient to the probe only) and its accuracy."""
        summary = torch.cat([z.mean(dim=-1), z.std(dim=-1)], dim=1)
        probe_logits = self.probe(summary.detach())
        probe_ce = F.cross_entropy(probe_logits, m.style)
        acc = (probe_logits.argmax(dim=1) == m.style).float().mean().detach()
        keep = m.label >= 0 if m.label is not None else torch.zeros_like(m.style, dtype=torch.bool)
        if not keep.any():
            return torch.zeros(()), probe_ce, acc
        logits = F.linear(summary[keep], self.probe.weight.detach(), self.probe.bias.detach())
        prior = self.style_prior[m.label[keep]]
        kl = (prior * (torch.log(prior.clamp_min(1e-12)) - F.log_softmax(logits, dim=1))).sum(1)
        return kl.mean(), probe_ce, acc

    def discriminator(
        self,
        m: Batch,
        x: Batch,
        fake_in: torch.Tensor,
        r1: bool,
        wild_in: torch.Tensor | None = None,
    ) -> tuple:
        """Discriminator loss and its parts, from the discriminator inputs of the translations
        to x (``fake_in``) and to r (``wild_in``) that :meth:`generator` returns. The content
        heads learn to reject the translations to r as well as those to x: the generator is
        scored on both, and a head that never saw translations to r had nothing to hold their
        scores back (fine-tuning runs drove them into the hundreds and collapsed)."""
        real_x = x.disc_input.requires_grad_(r1)
        all_x, all_m = self.d(real_x)[0], self.d(m.disc_input)[0]
        scores_x, scores_m = self.pick(all_x, x.style), self.pick(all_m, m.style)
        all_f = self.d(fake_in)[0]
        scores_f = self.pick(all_f, x.style)
        real = 0.5 * (F.relu(1 - scores_x).mean() + F.relu(1 - scores_m).mean())
        fake_loss = F.relu(1 + scores_f).mean()
        total = real + fake_loss
        logs = {"d_real": float(real.detach()), "d_fake": float(fake_loss.detach())}
        if self.cfg.w_style_cls > 0:
            logits_x, logits_m = self.style_logits(all_x), self.style_logits(all_m)
            cls = 0.5 * (F.cross_entropy(logits_x, x.style) + F.cross_entropy(logits_m, m.style))
            total = total + self.cfg.w_style_cls * cls
            with torch.no_grad():
                fake_right = self.style_logits(all_f).argmax(dim=1) == x.style
                real_right = torch.cat(
                    [logits_x.argmax(1) == x.style, logits_m.argmax(1) == m.style]
                )
            logs |= {
                "d_style_cls": float(cls.detach()),
                "d_style_acc_real": float(real_right.float().mean()),
                "d_style_acc_fake": float(fake_right.float().mean()),
            }
        if self.d.content_head is not None:
            content_x = self.pick_content(all_x, x.label)
            real_c = 0.5 * (
                self.hinge_mean(F.relu(1 - content_x))
                + self.hinge_mean(F.relu(1 - self.pick_content(all_m, m.label)))
            )
            fake_c = self.hinge_mean(F.relu(1 + self.pick_content(all_f, m.label)))
            if wild_in is not None:
                wild_scores = self.pick_content(self.d(wild_in)[0], m.label)
                fake_c = 0.5 * (fake_c + self.hinge_mean(F.relu(1 + wild_scores)))
            total = total + real_c + fake_c
            logs |= {
                "d_real_content": float(real_c.detach()),
                "d_fake_content": float(fake_c.detach()),
            }
            scores_x = torch.cat([scores_x, content_x])
        if r1:
            (grad,) = torch.autograd.grad(scores_x.sum(), real_x, create_graph=True)
            penalty = grad.pow(2).sum(dim=(1, 2)).mean()
            total = total + 0.5 * self.cfg.w_r1 * self.cfg.r1_every * penalty
            logs["r1"] = float(penalty.detach())
        return total, logs


# --------------------------------------------------------------------------- validation


VAL_METRICS = (
    "rec_pos_cm", "rec_rot", "self_pos_cm", "self_vel_cm_s", "style_acc_3d", "style_acc_2d",
    "joint",
)  # fmt: skip


class Validator:
    """Fixed held-out windows: reconstruction errors and style-code quality.

    - ``rec_pos_cm``/``rec_rot``: content m (held-out take) decoded with the 3D code of a
      training window of its own style: mean joint position error (cm, root-local) and
      L1 of standardised rotations;
    - ``self_pos_cm``: m decoded with its own code (plain autoencoding);
    - ``self_vel_cm_s``: the same decoding's joint velocity error (cm/s, root-local): how
      a wave stays a wave, which positions alone judge little;
    - ``style_acc_3d``/``style_acc_2d``: nearest style centroid (3D codes of training
      windows) of m's 3D code and of its 2D projection's code;
    - ``joint``: mean squared distance between m's 2D and 3D codes.
    """

    def __init__(self, prep: Prepared, cfg: TrainConfig, norm: Standardizer) -> None:
        rng = np.random.default_rng(cfg.seed + 7)
        items = TD.fixed_windows(
            prep.val, cfg.window, 3 * cfg.window // 4, cfg.val_windows, cfg.seed
        )
        self.m = to_batch(TD.cut(items, cfg.window), norm) if items else None
        sampler = TD.Sampler(prep.train, cfg.window, rng)
        present = [s for s in self.m.style.tolist() if s in sampler.by_style] if items else []
        self.ok = self.m is not None and len(present) == len(self.m.style)
        if self.ok:
            self.n = to_batch(TD.cut(sampler.pick(self.m.style.numpy()), cfg.window), norm)
        refs = sampler.pick(np.repeat(sampler.styles, 16))
        self.ref = to_batch(TD.cut(refs, cfg.window), norm)

    @torch.no_grad()
    def __call__(self, losses: Losses, chunk: int = 128) -> dict[str, float]:
        if not self.ok:
            return {}
        g = losses.g
        was_training = g.training
        g.eval()
        ref = self.ref.style3d
        ref_codes = torch.cat([g.style3d(ref[i : i + chunk]) for i in range(0, len(ref), chunk)])
        styles = torch.unique(self.ref.style)
        centroids = torch.stack([ref_codes[self.ref.style == s].mean(0) for s in styles])
        sums = dict.fromkeys(VAL_METRICS, 0.0)
        total = len(self.m.style)
        for i in range(0, total, chunk):
            sl = slice(i, i + chunk)
            m_content, m_pos, h = self.m.content[sl], self.m.positions[sl], self.m.hips_height[sl]
            zc = g.content_encoder(m_content)
            z3 = g.style3d(self.m.style3d[sl])
            z2 = g.style2d(self.m.style2d[sl])
            rec = g.decoder(zc, g.style3d(self.n.style3d[sl]))
            own = g.decoder(zc, z3)
            k = len(z3)
            err = (losses.positions(rec, h) - m_pos).norm(dim=-1).mean() * Fe.LEG
            sums["rec_pos_cm"] += float(err) * k
            sums["rec_rot"] += float(F.l1_loss(rec, m_content[:, : Fe.OUTPUT_CHANNELS])) * k
            own_pos = losses.positions(own, h)
            err = (own_pos - m_pos).norm(dim=-1).mean() * Fe.LEG
            sums["self_pos_cm"] += float(err) * k
            own_vel = own_pos.diff(dim=1) - m_pos.diff(dim=1)
            sums["self_vel_cm_s"] += float(own_vel.norm(dim=-1).mean()) * Fe.LEG * C.FPS * k
            truth = self.m.style[sl]
            for name, z in (("style_acc_3d", z3), ("style_acc_2d", z2)):
                nearest = styles[torch.cdist(z, centroids).argmin(dim=1)]
                sums[name] += float((nearest == truth).float().sum())
            sums["joint"] += float(F.mse_loss(z2, z3)) * k
        g.train(was_training)
        return {k: v / total for k, v in sums.items()}


# --------------------------------------------------------------------------- checkpoints


def _compact(optimizer_state: dict) -> dict:
    """Adam moments as bfloat16: halves the checkpoint; load_state_dict casts them back."""
    state = {
        k: {n: (t.to(torch.bfloat16) if n.startswith("exp_avg") else t) for n, t in s.items()}
        for k, s in optimizer_state["state"].items()
    }
    return {"state": state, "param_groups": optimizer_state["param_groups"]}


def save_checkpoint(path: Path, payload: dict, stats: Fe.FeatureStats, run_config: dict) -> None:
    """Write the checkpoint atomically, with ``<stem>_stats.npz`` and ``<stem>_config.json``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    Fe.save_stats(path.with_name(f"{path.stem}_stats.npz"), stats)
    path.with_name(f"{path.stem}_config.json").write_text(json.dumps(run_config, indent=2) + "\n")


def stats_to_dict(stats: Fe.FeatureStats) -> dict:
    return {k: {"mean": stats.mean[k], "std": stats.std[k]} for k in stats.mean}


def stats_from_dict(d: dict) -> Fe.FeatureStats:
    return Fe.FeatureStats(
        {k: np.asarray(v["mean"]) for k, v in d.items()},
        {k: np.asarray(v["std"]) for k, v in d.items()},
    )


def style_prior(prep: Prepared, label_index: dict[str, int]) -> torch.Tensor:
    """``(content labels, styles)``: per label, the styles that perform it, each by its
    share of that style's training frames (the sampler draws styles alike), rows summing
    to 1; a label no training clip performs is spread evenly."""
    frames = np.zeros((len(label_index), len(prep.styles)))
    per_style = np.zeros(len(prep.styles))
    for c in prep.train:
        per_style[c.style] += c.num_frames
        if c.label in label_index:
            frames[label_index[c.label], c.style] += c.num_frames
    share = frames / np.maximum(per_style, 1)[None]
    totals = share.sum(axis=1, keepdims=True)
    prior = np.where(totals > 0, share / np.maximum(totals, 1e-12), 1.0 / len(prep.styles))
    return torch.tensor(prior, dtype=torch.float32)


def load_translator(path: str | Path) -> tuple[Translator, Fe.FeatureStats, dict]:
    """The generator (eval mode), its statistics and the checkpoint's metadata."""
    ckpt = torch.load(path, map_location="cpu", weights_only=False)
    g = Translator(ModelConfig(**ckpt["model_config"]))
    g.load_state_dict(ckpt["generator"])
    g.eval()
    meta = {k: ckpt[k] for k in ("step", "styles", "val_takes", "train_config", "model_config")}
    return g, stats_from_dict(ckpt["stats"]), meta


def _optimizer_names(g: Translator, groups: int) -> list[list[str]]:
    """The generator's parameter names in the order each of ``opt_g``'s groups holds them."""
    names = [name for name, _ in g.named_parameters()]
    plain = [n for n in names if not n.endswith(AMPLITUDE_PARAMETERS)]
    kept = [n for n in names if n.endswith(AMPLITUDE_PARAMETERS)]
    return [plain, kept][:groups]


def grow_decoder(ckpt: dict, extra: int) -> dict:
    """``ckpt`` with ``extra`` more AdaIN residual blocks in the decoder, each starting as
    the identity, so the grown generator translates exactly as before and training goes
    on from there (more room for style without training from scratch).

    A new block's second AdaIN scale starts at 0 (its MLP rows give ``1 + s2 = 0``,
    ``b2 = 0``): the block adds nothing, yet the gradient reaches those rows at once and
    through them the block's convolutions. Its kept-amplitude references are the last old
    block's (same level). Adam's moments follow each old parameter to its new place; the
    MLP's new rows and the new blocks start with none."""
    if extra <= 0:
        return ckpt
    old_cfg = ModelConfig(**ckpt["model_config"])
    new_cfg = dataclasses.replace(old_cfg, decoder_resblocks=old_cfg.decoder_resblocks + extra)
    old_g, new_g = Translator(old_cfg), Translator(new_cfg)
    old_g.load_state_dict(ckpt["generator"])
    channels = old_cfg.content_channels[-1]
    at = 4 * channels * old_cfg.decoder_resblocks  # the new blocks' rows follow the old blocks'
    rows = 4 * channels * extra
    last = f"decoder.mlp.{len(new_g.decoder.mlp) - 1}"

    def widened(t: torch.Tensor, fill: torch.Tensor) -> torch.Tensor:
        return torch.cat([t[:at], fill.to(t.dtype), t[at:]])

    state = new_g.state_dict()
    for name, value in ckpt["generator"].items():
        if name not in (f"{last}.weight", f"{last}.bias"):
            state[name] = value
    state[f"{last}.weight"] = widened(
        ckpt["generator"][f"{last}.weight"], torch.zeros(rows, old_cfg.mlp_hidden)
    )
    bias = torch.zeros(extra, 4, channels)
    bias[:, 2] = -1.0  # s2: the second AdaIN's scale 1 + s2 starts at 0
    state[f"{last}.bias"] = widened(ckpt["generator"][f"{last}.bias"], bias.reshape(-1))
    if old_cfg.keep_amplitude:
        source = f"decoder.res.{old_cfg.decoder_resblocks - 1}"
        for k in range(old_cfg.decoder_resblocks, new_cfg.decoder_resblocks):
            for norm in ("norm1", "norm2"):
                state[f"decoder.res.{k}.{norm}.log_ref"] = ckpt["generator"][
                    f"{source}.{norm}.log_ref"
                ].clone()
    new_g.load_state_dict(state)

    def widen_moments(name: str, m: dict) -> dict:
        if name.startswith(last):
            fill = torch.zeros((rows, *m["exp_avg"].shape[1:]))
            m["exp_avg"] = widened(m["exp_avg"], fill)
            m["exp_avg_sq"] = widened(m["exp_avg_sq"], fill)
        return m

    return ckpt | {
        "model_config": new_cfg.to_dict(),
        "generator": new_g.state_dict(),
        "opt_g": _moved_adam(ckpt["opt_g"], old_g, new_g, widen_moments),
    }


def mix_kernels(ckpt: dict, kernels: int, spread: float = 0.05, seed: int = 0) -> dict:
    """``ckpt`` with each decoder residual convolution turned into a mix of ``kernels``
    kernels (:class:`MixedConv`), each the old kernel plus its own small perturbation
    (``spread`` times the kernel's spread) that sums to zero over the kernels. Mixing
    logits start at zero, so the generator translates exactly as before; the
    perturbations make the mix's gradient non-zero, so the kernels can part. Adam's
    moments of an old kernel are repeated for each of its copies."""
    old_cfg = ModelConfig(**ckpt["model_config"])
    if old_cfg.style_kernels:
        raise SystemExit("the checkpoint's decoder already mixes kernels")
    new_cfg = dataclasses.replace(old_cfg, style_kernels=kernels)
    old_g, new_g = Translator(old_cfg), Translator(new_cfg)
    old_g.load_state_dict(ckpt["generator"])
    gen = torch.Generator().manual_seed(seed)
    state = new_g.state_dict()
    mixed = {n for n, m in new_g.named_modules() if isinstance(m, MixedConv)}
    for name, value in ckpt["generator"].items():
        module, _, kind = name.rpartition(".")
        if module not in mixed:
            state[name] = value
            continue
        noise = torch.randn((kernels, *value.shape), generator=gen)
        noise = (noise - noise.mean(dim=0)) * spread * value.std()
        state[name] = (value.unsqueeze(0) + noise).flatten(0, 1)
    new_g.load_state_dict(state)

    def repeat_moments(name: str, m: dict) -> dict:
        if name.rpartition(".")[0] in mixed:
            for key in ("exp_avg", "exp_avg_sq"):
                m[key] = m[key].repeat(kernels, *[1] * (m[key].dim() - 1))
        return m

    return ckpt | {
        "model_config": new_cfg.to_dict(),
        "generator": new_g.state_dict(),
        "opt_g": _moved_adam(ckpt["opt_g"], old_g, new_g, repeat_moments),
    }


def _moved_adam(opt: dict, old_g: Translator, new_g: Translator, adjust=None) -> dict:
    """``opt_g``'s state for ``new_g``: each old parameter's Adam moments follow it to its
    new place (``adjust(name, moments)`` may reshape them); new parameters start with none."""
    old_names = _optimizer_names(old_g, len(opt["param_groups"]))
    new_names = _optimizer_names(new_g, len(opt["param_groups"]))
    moments = {}
    for group, names in zip(opt["param_groups"], old_names, strict=True):
        for index, name in zip(group["params"], names, strict=True):
            if index in opt["state"]:
                moments[name] = opt["state"][index]
    new_state, groups, index = {}, [], 0
    for group, names in zip(opt["param_groups"], new_names, strict=True):
        groups.append(group | {"params": list(range(index, index + len(names)))})
        for name in names:
            if name in moments:
                m = dict(moments[name])
                new_state[index] = adjust(name, m) if adjust else m
            index += 1
    return {"state": new_state, "param_groups": groups}


@torch.no_grad()
def narrow_content(ckpt: dict, channels: int, prep: Prepared, window: int) -> dict:
    """``ckpt`` with its content code squeezed through ``channels`` channels, starting as the
    projection onto the codes' top principal components (over the training clips' windows,
    half-overlapping): the generator starts as that projection leaves it, and learns on."""
    old_cfg = ModelConfig(**ckpt["model_config"])
    if old_cfg.content_bottleneck:
        raise SystemExit("the checkpoint's content code already has a bottleneck")
    if not 0 < channels <= old_cfg.content_channels[-1]:
        raise SystemExit(
            f"--content-bottleneck {channels}: the content code has "
            f"{old_cfg.content_channels[-1]} channels"
        )
    new_cfg = dataclasses.replace(old_cfg, content_bottleneck=channels)
    old_g, new_g = Translator(old_cfg), Translator(new_cfg)
    old_g.load_state_dict(ckpt["generator"])
    old_g.eval()
    norm = Standardizer(prep.stats)
    windows = [
        clip.content[start : start + window].T
        for clip in prep.train
        for start in range(0, len(clip.content) - window + 1, window // 2)
    ]
    codes = []
    for i in range(0, len(windows), 256):
        x = torch.from_numpy(np.stack(windows[i : i + 256]).astype(np.float32))
        z = old_g.content_encoder(norm.content.standardize(x))
        codes.append(z.transpose(1, 2).reshape(-1, z.shape[1]))
    z = torch.cat(codes).double()
    mean = z.mean(0)
    basis = torch.linalg.svd(z - mean, full_matrices=False).Vh[:channels]  # (k, C)
    state = new_g.state_dict() | ckpt["generator"]
    state["content_encoder.bottleneck.0.weight"] = basis[:, :, None].float()
    state["content_encoder.bottleneck.0.bias"] = -(basis @ mean).float()
    state["content_encoder.bottleneck.1.weight"] = basis.T[:, :, None].float()
    state["content_encoder.bottleneck.1.bias"] = mean.float()
    new_g.load_state_dict(state)
    return ckpt | {
        "model_config": new_cfg.to_dict(),
        "generator": new_g.state_dict(),
        "opt_g": _moved_adam(ckpt["opt_g"], old_g, new_g),
    }


# --------------------------------------------------------------------------- loop


def lr_at(step: int, cfg: TrainConfig) -> float:
    progress = min(step / max(cfg.steps, 1), 1.0)
    low = cfg.lr * cfg.lr_final_fraction
    return low + 0.5 * (cfg.lr - low) * (1 + math.cos(math.pi * progress))


def train(
    cfg: TrainConfig,
    checkpoint: Path,
    log_dir: Path,
    resume: bool,
    max_steps: int | None,
    model_cfg: ModelConfig | None = None,
    keep_amplitude: bool = False,
    grow: int = 0,
    bottleneck: int = 0,
    style_kernels: int = 0,
) -> dict:
    """Train (or go on training) until ``cfg.steps``, or ``max_steps`` more steps.
    ``keep_amplitude`` turns :class:`Norm`'s kept amplitude on, for a resumed model too;
    ``grow`` adds that many decoder blocks to a resumed model (:func:`grow_decoder`);
    ``bottleneck`` squeezes the content code through that many channels, a resumed model's
    by :func:`narrow_content`; ``style_kernels`` mixes that many kernels in each decoder
    residual convolution, a resumed model's by :func:`mix_kernels`."""
    from torch.utils.tensorboard import SummaryWriter
    from tqdm import tqdm

    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=False) if resume else None
    if ckpt is not None:
        ckpt = grow_decoder(ckpt, grow)
        if style_kernels:
            ckpt = mix_kernels(ckpt, style_kernels)
        model_cfg = ModelConfig(**ckpt["model_config"])
    prep = prepare(cfg, ckpt["val_takes"] if ckpt else None)
    if ckpt is not None:
        prep.stats = stats_from_dict(ckpt["stats"])  # keep the statistics the weights know
        if bottleneck:
            ckpt = narrow_content(ckpt, bottleneck, prep, cfg.window)
            model_cfg = ModelConfig(**ckpt["model_config"])
        if ckpt["styles"] != prep.styles:
            raise SystemExit(
                f"checkpoint styles {ckpt['styles']} differ from the data's {prep.styles}"
            )
    model_cfg = model_cfg or ModelConfig()
    model_cfg.keep_amplitude |= keep_amplitude
    if ckpt is None:  # replace, not assign: the config checks the values
        model_cfg = dataclasses.replace(
            model_cfg,
            content_bottleneck=bottleneck or model_cfg.content_bottleneck,
            style_kernels=style_kernels or model_cfg.style_kernels,
        )
    model_cfg.num_styles = len(prep.styles)
    if cfg.w_content_adv > 0 and not model_cfg.num_contents:
        model_cfg.num_contents = len(prep.contents)
    if (
        ckpt is not None
        and model_cfg.num_contents
        and ckpt.get("contents", prep.contents) != prep.contents
    ):
        raise SystemExit(
            f"checkpoint content labels {ckpt['contents']} differ from the data's {prep.contents}"
        )
    label_index = {label: i for i, label in enumerate(prep.contents)}

    torch.manual_seed(cfg.seed)
    g, d = Translator(model_cfg), Discriminator(model_cfg)
    norm = Standardizer(prep.stats)
    probe = opt_probe = None
    if cfg.w_content_style > 0:
        probe = torch.nn.Linear(2 * model_cfg.content_channels[-1], model_cfg.num_styles)
        opt_probe = torch.optim.Adam(probe.parameters(), lr=cfg.probe_lr)
    prior = style_prior(prep, label_index) if probe is not None else None
    losses = Losses(g, d, norm, cfg, probe, prior)
    amplitude = [p for name, p in g.named_parameters() if name.endswith(AMPLITUDE_PARAMETERS)]
    opt_g = torch.optim.Adam(
        [p for name, p in g.named_parameters() if not name.endswith(AMPLITUDE_PARAMETERS)],
        lr=cfg.lr,
        betas=(0.5, 0.999),
    )
    head = [p for name, p in d.named_parameters() if name.startswith("content_head.")]
    body = [p for name, p in d.named_parameters() if not name.startswith("content_head.")]
    opt_d = torch.optim.Adam(body, lr=cfg.lr, betas=(0.5, 0.999))

    def add_content_head_group() -> None:
        opt_d.add_param_group({"params": head, "lr_scale": cfg.content_head_lr_scale})

    def add_amplitude_group() -> None:
        opt_g.add_param_group({"params": amplitude, "lr_scale": cfg.amplitude_lr_scale})

    rng = np.random.default_rng(cfg.seed)
    step = 0
    calibrate = bool(amplitude)
    if ckpt is not None:
        # a generator trained with plain instance norm gets fresh kept amplitudes
        missing, unexpected = g.load_state_dict(ckpt["generator"], strict=False)
        if unexpected or any(not k.endswith(AMPLITUDE_PARAMETERS) for k in missing):
            raise SystemExit(f"generator weights do not fit: {missing} {unexpected}")
        calibrate = bool(missing)
        if amplitude and len(ckpt["opt_g"]["param_groups"]) > 1:
            add_amplitude_group()
        # a discriminator trained without content heads gets fresh ones
        missing, unexpected = d.load_state_dict(ckpt["discriminator"], strict=False)
        if unexpected or any(not k.startswith("content_head.") for k in missing):
            raise SystemExit(f"discriminator weights do not fit: {missing} {unexpected}")
        opt_g.load_state_dict(ckpt["opt_g"])
        if head and len(ckpt["opt_d"]["param_groups"]) > 1:
            add_content_head_group()
        opt_d.load_state_dict(ckpt["opt_d"])
        if probe is not None and "probe" in ckpt:
            probe.load_state_dict(ckpt["probe"])
            opt_probe.load_state_dict(ckpt["opt_probe"])
            for group in opt_probe.param_groups:  # the run's rate, not the saved one
                group["lr"] = cfg.probe_lr
        step = int(ckpt["step"])
        rng.bit_generator.state = ckpt["numpy_rng"]
        torch.set_rng_state(ckpt["torch_rng"])
    if head and len(opt_d.param_groups) == 1:
        add_content_head_group()
    if amplitude and len(opt_g.param_groups) == 1:
        add_amplitude_group()

    sampler = TD.Sampler(prep.train, cfg.window, rng)
    alignments = TD.Alignments()
    if calibrate:
        items = sampler.pick(sampler.random_styles(CALIBRATION_WINDOWS))
        batch = to_batch(TD.cut(items, cfg.window, rng), norm)
        calibrate_amplitude(g, batch.content, batch.style3d)
    validator = Validator(prep, cfg, norm)
    run_config = {
        "model": model_cfg.to_dict(),
        "train": asdict(cfg),
        "styles": prep.styles,
        "val_takes": prep.val_takes,
        "stride": STRIDE,
        "features": {
            "content": Fe.CONTENT_CHANNELS, "output": Fe.OUTPUT_CHANNELS,
            "style3d": Fe.STYLE3D_CHANNELS, "style2d": Fe.STYLE2D_CHANNELS, "fps": Fe.FPS,
        },
        "parameters": {"generator": count_parameters(g), "discriminator": count_parameters(d)},
        "train_clips": len(prep.train), "val_clips": len(prep.val),
        "extra_clips": len(prep.extra),
    }  # fmt: skip

    def save(metrics: dict) -> None:
        payload = {
            "format": 1,
            "step": step,
            "model_config": model_cfg.to_dict(),
            "train_config": asdict(cfg),
            "styles": prep.styles,
            "contents": prep.contents,
            "val_takes": prep.val_takes,
            "stats": stats_to_dict(prep.stats),
            "generator": g.state_dict(),
            "discriminator": d.state_dict(),
            "opt_g": _compact(opt_g.state_dict()),
            "opt_d": _compact(opt_d.state_dict()),
            "numpy_rng": rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "metrics": metrics,
        }
        if probe is not None:
            payload |= {"probe": probe.state_dict(), "opt_probe": opt_probe.state_dict()}
        save_checkpoint(
            checkpoint, payload, prep.stats, run_config | {"step": step, "metrics": metrics}
        )

    writer = SummaryWriter(str(log_dir), purge_step=step if step else None)
    end = cfg.steps if max_steps is None else min(cfg.steps, step + max_steps)
    print(
        f"translator: {len(prep.train)} train / {len(prep.val)} val clips, {len(prep.styles)} styles, "
        f"G {count_parameters(g):,} D {count_parameters(d):,} parameters, step {step} -> {end}",
        flush=True,
    )
    metrics: dict = {}
    best_rec = float((ckpt or {}).get("metrics", {}).get("rec_pos_cm", math.inf))
    saved_step = step if ckpt is not None else None
    last_save = time.monotonic()
    started, start_step = time.monotonic(), step
    bar = tqdm(total=cfg.steps, initial=step, mininterval=30, file=sys.stderr, dynamic_ncols=False)
    g.train()
    d.train()
    while step < end:
        lr = lr_at(step, cfg)
        for opt in (opt_g, opt_d):
            for group in opt.param_groups:
                group["lr"] = lr * group.get("lr_scale", 1.0)
        styles_m = sampler.random_styles(cfg.batch_size)
        items_m = sampler.pick(styles_m)
        items_n = sampler.pick(styles_m)
        same = rng.random(cfg.batch_size) < cfg.p_self
        items_n = [a if s else b for a, b, s in zip(items_m, items_n, same, strict=True)]
        if cfg.pair_content:
            labels = [c.label for c, _ in items_m]
            items_x = sampler.pick(sampler.other_styles_performing(styles_m, labels), labels)
        else:
            items_x = sampler.pick(sampler.other_styles(styles_m))
        m, n, x = (
            to_batch(TD.cut(it, cfg.window, rng), norm) for it in (items_m, items_n, items_x)
        )
        for batch, items in ((m, items_m), (x, items_x)):
            batch.label = torch.tensor([label_index.get(c.label, -1) for c, _ in items])
        r = None
        # x is content-matched; r is any style, or with w_raised_hands a style that never
        # performs m's content: styles that do are judged against their own takes
        if (cfg.w_cycle > 0 or cfg.w_raised_hands > 0) and cfg.pair_content:
            styles_r = (
                sampler.other_styles_not_performing(styles_m, labels)
                if cfg.w_raised_hands > 0
                else sampler.other_styles(styles_m)
            )
            r = to_batch(TD.cut(sampler.pick(styles_r), cfg.window), norm)

        e = None
        if prep.extra:
            e = to_batch(
                TD.cut(TD.random_windows(prep.extra, cfg.window, cfg.extra_batch, rng), cfg.window),
                norm,
            )

        paired = None
        if cfg.w_paired > 0 or cfg.w_paired_vel > 0:
            target, mask = alignments.targets(items_m, items_x, cfg.window)
            paired = (torch.from_numpy(target), torch.from_numpy(mask))

        ramp = min(1.0, step / max(cfg.adv_warmup, 1))
        loss_g, logs, fake_in, wild_in = losses.generator(m, n, x, ramp, r, e, paired)
        opt_g.zero_grad(set_to_none=True)
        if opt_probe is not None:
            opt_probe.zero_grad(set_to_none=True)
        loss_g.backward()
        opt_g.step()
        if opt_probe is not None:
            opt_probe.step()

        loss_d, logs_d = losses.discriminator(m, x, fake_in, step % cfg.r1_every == 0, wild_in)
        opt_d.zero_grad(set_to_none=True)
        loss_d.backward()
        opt_d.step()
        step += 1
        bar.update(1)

        if step % 50 == 0 or step == end:
            for k, v in (logs | logs_d).items():
                writer.add_scalar(f"train/{k}", v, step)
            writer.add_scalar("train/lr", lr, step)
            rate = (step - start_step) / max(time.monotonic() - started, 1e-9)
            writer.add_scalar("train/steps_per_s", rate, step)
        if step % cfg.val_every == 0 or step == end:
            metrics = validator(losses)
            for k, v in metrics.items():
                writer.add_scalar(f"val/{k}", v, step)
            shown = " ".join(f"{k}={v:.3f}" for k, v in metrics.items())
            print(f"step {step}: rec_pos_cm={logs['rec_pos_cm']:.2f} val {shown}", flush=True)
            if metrics["rec_pos_cm"] > cfg.diverged_factor * best_rec:
                bar.close()
                writer.close()
                kept = f"keeps step {saved_step}" if saved_step is not None else "was not written"
                raise SystemExit(
                    f"translator training diverged at step {step}: validation rec_pos_cm "
                    f"{metrics['rec_pos_cm']:.2f} is over {cfg.diverged_factor} x the run's best "
                    f"{best_rec:.2f}; the checkpoint {checkpoint} {kept}"
                )
            if step >= cfg.adv_warmup:
                best_rec = min(best_rec, metrics["rec_pos_cm"])
        if time.monotonic() - last_save > 60 * cfg.checkpoint_minutes or step == end:
            save(metrics)
            saved_step = step
            last_save = time.monotonic()
    bar.close()
    writer.close()
    rate = (step - start_step) / max(time.monotonic() - started, 1e-9)
    print(f"done: step {step}, {rate:.2f} steps/s, checkpoint {checkpoint}", flush=True)
    return {"step": step, "steps_per_s": rate, "metrics": metrics}


# --------------------------------------------------------------------------- CLI


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m training.translator", description=__doc__.split("\n")[0]
    )
    defaults = TrainConfig()
    for f in dataclasses.fields(TrainConfig):
        if f.name == "datasets":
            parser.add_argument("--datasets", type=int, nargs="+", default=None)
            continue
        kind = type(getattr(defaults, f.name))
        parser.add_argument(
            f"--{f.name.replace('_', '-')}",
            type=(lambda v: v.lower() in ("1", "true", "yes")) if kind is bool else kind,
            default=None,
            help=f"default {getattr(defaults, f.name)}",
        )
    parser.add_argument("--checkpoint", type=Path, default=DEFAULT_CHECKPOINT)
    parser.add_argument("--log-dir", type=Path, default=DEFAULT_LOG_DIR)
    parser.add_argument("--resume", action="store_true", help="go on from --checkpoint")
    parser.add_argument("--max-steps", type=int, default=None, help="stop after this many steps")
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch intra-op threads (default 1: on shared cores more threads spin and run ~10x slower)",
    )
    parser.add_argument("--width", type=float, default=1.0, help="scale every channel count")
    parser.add_argument(
        "--keep-amplitude",
        action="store_true",
        help="let every instance norm learn to keep some of its input's amplitude "
        "(a resumed model starts where it was)",
    )
    parser.add_argument(
        "--grow-decoder",
        type=int,
        default=0,
        help="with --resume: add this many AdaIN residual blocks to the decoder, each "
        "starting as the identity",
    )
    parser.add_argument(
        "--content-bottleneck",
        type=int,
        default=0,
        help="squeeze the content code through this many channels (a resumed model's "
        "starts as the projection onto its codes' top principal components)",
    )
    parser.add_argument(
        "--style-kernels",
        type=int,
        default=0,
        help="mix this many kernels, weighted by the style code, in each decoder residual "
        "convolution (a resumed model's start as copies of its kernels, translating as before)",
    )
    args = parser.parse_args(argv)
    if args.grow_decoder and not args.resume:
        parser.error("--grow-decoder needs --resume (a fresh model takes its size from the config)")

    given = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(TrainConfig)
        if getattr(args, f.name) is not None
    }
    if "datasets" in given:
        given["datasets"] = tuple(given["datasets"])
    base = {}
    if args.resume:
        if not args.checkpoint.exists():
            raise SystemExit(f"--resume: no checkpoint at {args.checkpoint}")
        base = torch.load(args.checkpoint, map_location="cpu", weights_only=False)["train_config"]
        base["datasets"] = tuple(base["datasets"])
    cfg = TrainConfig(**(base | given))
    max_steps = args.max_steps
    if os.environ.get("MOTION_SMOKE") == "1":
        max_steps = min(max_steps or 3, 3)
    if args.threads:
        torch.set_num_threads(args.threads)
    model_cfg = None
    if args.width != 1.0:
        base_model = ModelConfig()
        scale = lambda cs: [max(8, int(round(c * args.width / 8)) * 8) for c in cs]  # noqa: E731
        model_cfg = dataclasses.replace(
            base_model,
            content_channels=scale(base_model.content_channels),
            style_channels=scale(base_model.style_channels),
            disc_channels=scale(base_model.disc_channels),
            style_dim=scale([base_model.style_dim])[0],
            mlp_hidden=scale([base_model.mlp_hidden])[0],
        )
    train(
        cfg,
        args.checkpoint,
        args.log_dir,
        args.resume,
        max_steps,
        model_cfg,
        args.keep_amplitude,
        args.grow_decoder,
        args.content_bottleneck,
        args.style_kernels,
    )

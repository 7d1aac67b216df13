"""Bandai clips as translator features, and the batches of a training step.

Every clip is encoded once by ``motion.features`` (content, 3D style, global positions);
windows of ``T`` frames are cut at random starts (a superset of the paper's windows with
overlap T/4), styles drawn uniformly so that rare styles get their share of the
discriminator. 2D style inputs come from a bank of ``views`` projections of each whole
clip (random yaw and scale, paper section 3.3) made once through
``motion.features.style2d_from_positions``, the normalisation the service's keypoint path
shares; whole clips, because a video is normalised as a whole too, and once, because the
projection costs about a millisecond per call.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from motion import canonical as C
from motion import features as Fe
from training.data import Clip


@dataclass
class EncodedClip:
    """One clip's features: ``content (F, 130)``, ``style3d (F, 63)``, 2D views
    ``style2d (V, F, 32)`` float32, its style index, take and content label."""

    content: np.ndarray
    style3d: np.ndarray
    style2d: np.ndarray
    style: int
    take: str
    label: str | None = None  # what is performed (Bandai content: walk, wave-left-hand...)

    @property
    def num_frames(self) -> int:
        return len(self.content)


# What a Bandai action becomes performed the other way round; the rest keep their name (a
# bye or a guide with the other hand is still one).
MIRRORED_CONTENT = {
    "walk-left": "walk-right", "walk-right": "walk-left",
    "walk-turn-left": "walk-turn-right", "walk-turn-right": "walk-turn-left",
    "raise-up-left-hand": "raise-up-right-hand", "raise-up-right-hand": "raise-up-left-hand",
    "wave-left-hand": "wave-right-hand", "wave-right-hand": "wave-left-hand",
}  # fmt: skip


def mirrored_clip(clip: Clip) -> Clip:
    """``clip`` performed with left and right swapped (``motion.canonical.mirrored``): the
    same style (a style has no side), the action renamed where it names a side, and a take
    of its own (``<take>~mirrored``)."""
    motion = C.mirrored(clip.motion)
    content = MIRRORED_CONTENT.get(clip.content, clip.content) if clip.content else None
    return replace(
        clip,
        name=f"{clip.name}~mirrored",
        take=f"{clip.take}~mirrored",
        lrot=motion.lrot.astype(np.float32),
        root=motion.lpos[:, 1].astype(np.float32),  # the hips carry the travel
        content=content,
    )


def project_views(
    gpos: np.ndarray, rng: np.random.Generator, views: int, toe_drop: float = 0.25
) -> np.ndarray:
    """2D style inputs ``(views, F, STYLE2D_CHANNELS)`` float32 of ``gpos (F, 22, 3)``.

    Yaw uniform in [-90, 90] degrees and scale in [0.8, 1.2] (paper); with probability
    ``toe_drop`` a view's toes sit on the ankles, as keypoint layouts without toes
    (COCO) give them.
    """
    toes = [C.INDEX["Toes_L"], C.INDEX["Toes_R"]]
    feet = [C.INDEX["Foot_L"], C.INDEX["Foot_R"]]
    out = np.empty((views, len(gpos), Fe.STYLE2D_CHANNELS), dtype=np.float32)
    for v in range(views):
        g = gpos
        if rng.random() < toe_drop:
            g = gpos.copy()
            g[:, toes] = g[:, feet]
        yaw = np.deg2rad(rng.uniform(-90.0, 90.0))
        out[v] = Fe.style2d_from_positions(g, yaw, rng.uniform(0.8, 1.2))
    return out


def encode_clips(
    clips: list[Clip], styles: list[str], min_frames: int, views: int, seed: int
) -> list[EncodedClip]:
    """Clips with at least ``min_frames`` frames, encoded with ``views`` 2D projections each;
    ``styles`` gives the style indices (-1 for a clip without a style)."""
    index = {s: i for i, s in enumerate(styles)}
    rng = np.random.default_rng(seed)
    out = []
    for clip in clips:
        if clip.num_frames < min_frames:
            continue
        enc = Fe.encode(clip.motion)
        style2d = project_views(enc.gpos, rng, views)
        out.append(
            EncodedClip(
                enc.content,
                enc.style3d,
                style2d,
                -1 if clip.style is None else index[clip.style],
                clip.take,
                clip.content,
            )
        )
    return out


@dataclass
class Windows:
    """A batch of windows, frames first: ``content (B, T, 130)``, ``style3d (B, T, 63)``,
    ``style2d (B, T, 32)`` (one random view each), ``style (B,)``."""

    content: np.ndarray
    style3d: np.ndarray
    style2d: np.ndarray
    style: np.ndarray


def cut(
    items: list[tuple[EncodedClip, int]], length: int, rng: np.random.Generator | None = None
) -> Windows:
    """Windows of ``length`` frames at the given ``(clip, start)`` pairs; the 2D view is
    random with ``rng``, else the first."""
    views = [int(rng.integers(len(c.style2d))) if rng is not None else 0 for c, _ in items]
    return Windows(
        content=np.stack([c.content[s : s + length] for c, s in items]),
        style3d=np.stack([c.style3d[s : s + length] for c, s in items]),
        style2d=np.stack(
            [c.style2d[v, s : s + length] for (c, s), v in zip(items, views, strict=True)]
        ),
        style=np.array([c.style for c, _ in items]),
    )


class Sampler:
    """Random windows by style: ``draw(styles)`` gives one window per requested style."""

    def __init__(self, clips: list[EncodedClip], length: int, rng: np.random.Generator) -> None:
        self.length = length
        self.rng = rng
        self.by_style: dict[int, list[EncodedClip]] = {}
        for c in clips:
            if c.num_frames >= length:
                self.by_style.setdefault(c.style, []).append(c)
        self.styles = np.array(sorted(self.by_style))
        # clips weighted by how many windows they hold
        self.weights = {
            s: np.array([c.num_frames - length + 1 for c in cs], dtype=np.float64)
            for s, cs in self.by_style.items()
        }
        for w in self.weights.values():
            w /= w.sum()
        # content-matched draws: (style, label) -> clips and weights; label -> styles
        grouped: dict[tuple[int, str], list[EncodedClip]] = {}
        for s, cs in self.by_style.items():
            for c in cs:
                if c.label is not None:
                    grouped.setdefault((s, c.label), []).append(c)
        self.by_style_label = {}
        self.styles_of: dict[str, list[int]] = {}
        for (s, label), cs in sorted(grouped.items()):
            w = np.array([c.num_frames - length + 1 for c in cs], dtype=np.float64)
            self.by_style_label[s, label] = (cs, w / w.sum())
            self.styles_of.setdefault(label, []).append(s)

    def random_styles(self, count: int) -> np.ndarray:
        return self.rng.choice(self.styles, size=count)

    def other_styles(self, styles: np.ndarray) -> np.ndarray:
        """A different style for each entry (uniform among the others)."""
        offsets = self.rng.integers(1, len(self.styles), size=len(styles))
        pos = np.searchsorted(self.styles, styles)
        return self.styles[(pos + offsets) % len(self.styles)]

    def other_styles_performing(self, styles: np.ndarray, labels: list) -> np.ndarray:
        """For each entry a different style that performs the same content label in the
        data (uniform among them), any other style where none does."""
        return self._other_styles_among(styles, labels, lambda label: self.styles_of.get(label, ()))

    def other_styles_not_performing(self, styles: np.ndarray, labels: list) -> np.ndarray:
        """For each entry a different style that never performs the same content label in
        the data (uniform among them), any other style where every style does."""

        def never(label: str) -> list[int]:
            performing = set(self.styles_of.get(label, ()))
            return [t for t in self.styles if t not in performing]

        return self._other_styles_among(styles, labels, never)

    def _other_styles_among(self, styles: np.ndarray, labels: list, candidates) -> np.ndarray:
        """For each entry a style of ``candidates(label)`` other than its own (uniform),
        any other style where there is none."""
        out = self.other_styles(styles)
        for i, (s, label) in enumerate(zip(styles, labels, strict=True)):
            choices = [t for t in candidates(label) if t != s]
            if choices:
                out[i] = choices[self.rng.integers(len(choices))]
        return out

    def pick(self, styles: np.ndarray, labels: list | None = None) -> list[tuple[EncodedClip, int]]:
        """A random window of each style; of a clip with the given content label where
        ``labels`` names one the style performs."""
        items = []
        for i, s in enumerate(styles):
            cs, p = self.by_style[int(s)], self.weights[int(s)]
            label = labels[i] if labels is not None else None
            if label is not None and (int(s), label) in self.by_style_label:
                cs, p = self.by_style_label[int(s), label]
            clip = cs[self.rng.choice(len(cs), p=p)]
            items.append((clip, int(self.rng.integers(0, clip.num_frames - self.length + 1))))
        return items


def random_windows(
    clips: list[EncodedClip], length: int, count: int, rng: np.random.Generator
) -> list[tuple[EncodedClip, int]]:
    """``count`` windows at random starts, clips weighted by how many windows they hold."""
    clips = [c for c in clips if c.num_frames >= length]
    weights = np.array([c.num_frames - length + 1 for c in clips], dtype=np.float64)
    chosen = rng.choice(len(clips), size=count, p=weights / weights.sum())
    return [(clips[i], int(rng.integers(0, clips[i].num_frames - length + 1))) for i in chosen]


def fixed_windows(
    clips: list[EncodedClip], length: int, hop: int, limit: int, seed: int
) -> list[tuple[EncodedClip, int]]:
    """Evenly spaced windows (``hop`` frames apart) of the clips, at most ``limit`` of them
    chosen reproducibly by ``seed``: the validation set."""
    items = [
        (c, s)
        for c in clips
        if c.num_frames >= length
        for s in range(0, c.num_frames - length + 1, hop)
    ]
    rng = np.random.default_rng(seed)
    if len(items) > limit:
        items = [items[i] for i in sorted(rng.choice(len(items), size=limit, replace=False))]
    return items


ALIGN_VELOCITY_FRAMES = 1.0  # see alignment_features


def alignment_features(clip: EncodedClip) -> np.ndarray:
    """``(F, 126)`` what :func:`aligned_frames` matches: body joints relative to the hips
    (leg lengths) and their change over ``ALIGN_VELOCITY_FRAMES`` frames, which tells a
    hand going up from one coming down. Weighted more, velocities misalign performances
    at different speeds, which styles are (over 10 frames: 4 frames off on a clip slowed
    to a third of the pace, against half a frame over 1)."""
    pos = clip.style3d.reshape(clip.num_frames, -1, 3)
    rel = (pos - pos[:, :1]).reshape(clip.num_frames, -1)
    vel = np.gradient(rel, axis=0) * ALIGN_VELOCITY_FRAMES if clip.num_frames > 1 else 0 * rel
    return np.concatenate([rel, vel], axis=1)


def aligned_frames(a: EncodedClip, b: EncodedClip) -> np.ndarray:
    """For each frame of ``a``, the frame of ``b`` dynamic time warping matches it with
    (``librosa.sequence.dtw``, Euclidean on :func:`alignment_features`; the mean where it
    matches several): ``(a.num_frames,)`` int, non-decreasing, from 0 to b's last frame."""
    from librosa.sequence import dtw

    _, path = dtw(alignment_features(a).T, alignment_features(b).T, metric="euclidean")
    sums = np.zeros(a.num_frames)
    counts = np.zeros(a.num_frames)
    np.add.at(sums, path[:, 0], path[:, 1])
    np.add.at(counts, path[:, 0], 1)
    return np.rint(sums / counts).astype(np.int64)


class Alignments:
    """:func:`aligned_frames` of pairs of clips, each computed once, on first use."""

    def __init__(self) -> None:
        self._frames: dict[tuple[int, int], np.ndarray] = {}

    def __call__(self, a: EncodedClip, b: EncodedClip) -> np.ndarray:
        key = (id(a), id(b))
        if key not in self._frames:
            self._frames[key] = aligned_frames(a, b)
        return self._frames[key]

    def targets(
        self,
        items_m: list[tuple[EncodedClip, int]],
        items_x: list[tuple[EncodedClip, int]],
        length: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """For windows of m and the clips of x: ``(B, length, 21, 3)`` root-local positions
        of x's clip at the frames aligned with m's window (zeros where unpaired) and
        ``(B,)`` bool, paired where both clips perform the same content label in two
        styles."""
        out = np.zeros((len(items_m), length, len(Fe.BODY), 3), dtype=np.float32)
        paired = np.zeros(len(items_m), dtype=bool)
        for i, ((a, start), (b, _)) in enumerate(zip(items_m, items_x, strict=True)):
            if a.label is None or a.label != b.label or a.style == b.style:
                continue
            frames = self(a, b)[start : start + length]
            out[i] = b.style3d[frames].reshape(length, -1, 3)
            paired[i] = True
        return out, paired

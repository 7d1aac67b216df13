"""Bandai's pairs as supervised examples for the translator.

Bandai performs each action in many styles (dataset 1: 16 actions x 15 styles, dataset 2:
10 actions x 7 styles, walks and runs in both). A content window of take A and a target
style S give a supervised example wherever S performs A's action: the target is a take of
that action in S, aligned in time with A by dynamic time warping (:func:`align`). The
target style may be the content's own.

Styles are merged where the two datasets name one style twice (``motion.styles``).
Mirror images (left and right swapped) are separate takes, paired only with mirror
images.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from motion import canonical as C
from motion import features as Fe
from training.data import Clip, save_npz

MIRRORED = "~mirrored"  # the suffix of a mirror image's name and take
_SIDE_WORDS = {"left": "right", "right": "left", "Left": "Right", "Right": "Left",
               "LEFT": "RIGHT", "RIGHT": "LEFT"}  # fmt: skip


def mirrored_content(content: str) -> str:
    """What an action becomes performed the other way round: the words ``left`` and
    ``right`` swapped (``walk-left`` -> ``walk-right``, ``wave-left-hand`` ->
    ``wave-right-hand``); the rest keep their name (a bow is still a bow)."""
    return "".join(_SIDE_WORDS.get(w, w) for w in re.split(r"([^A-Za-z]+)", content))


def mirrored_clip(clip: Clip) -> Clip:
    """``clip`` performed with left and right swapped (``motion.canonical.mirrored``): the
    same style (a style has no side), the action renamed where it names a side, and a take
    of its own (``<take>~mirrored``)."""
    motion = C.mirrored(clip.motion)
    return replace(
        clip,
        name=f"{clip.name}{MIRRORED}",
        take=f"{clip.take}{MIRRORED}",
        lrot=motion.lrot.astype(np.float32),
        root=motion.lpos[:, 1].astype(np.float32),  # the hips carry the travel
        content=mirrored_content(clip.content) if clip.content else None,
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


SLOPES = np.array([[1, 1], [1, 2], [2, 1]])  # DTW steps: the target runs 0.5x to 2x as fast
ALIGN_SPEED_WEIGHT = 0.5  # velocities' weight beside poses in the alignment features


@dataclass
class Take:
    """One clip's features: ``content (F, 130)``, ``style3d (F, 63)`` and 2D views
    ``style2d (V, F, 32)`` float32; ``style`` index (-1: none), action label, mirror flag."""

    name: str
    content: np.ndarray
    style3d: np.ndarray
    style2d: np.ndarray
    style: int
    label: str | None
    mirrored: bool
    inputs: np.ndarray | None = None  # (F, 193) restyler input, once statistics are known

    @property
    def frames(self) -> int:
        return len(self.content)


def encode_takes(
    clips: list[Clip], styles: list[str], views: int, rng: np.random.Generator
) -> list[Take]:
    """Takes of ``clips`` and of the mirror images of those whose ``extra["mirror_ok"]``
    allows it (default yes), with ``views`` 2D projections each; style indices in
    ``styles`` (-1 where none)."""
    out = []
    for clip in clips:
        for flipped in (False, True) if clip.extra.get("mirror_ok", True) else (False,):
            c = mirrored_clip(clip) if flipped else clip
            enc = Fe.encode(c.motion)
            style = -1 if c.style is None else styles.index(c.style)
            out.append(
                Take(
                    c.name,
                    enc.content,
                    enc.style3d,
                    project_views(enc.gpos, rng, views),
                    style,
                    c.content,
                    flipped,
                )
            )
    return out


def alignment_features(take: Take) -> np.ndarray:
    """``(F, 120)`` poses relative to the hips and their velocities, each channel
    standardised over the take: the alignment follows the phase of the action, not the
    posture that the style changes."""
    pos = take.style3d.reshape(take.frames, -1, 3)
    rel = (pos[:, 1:] - pos[:, :1]).reshape(take.frames, -1).astype(np.float64)
    vel = np.gradient(rel, axis=0) if take.frames > 1 else np.zeros_like(rel)

    def z(x: np.ndarray) -> np.ndarray:
        return (x - x.mean(0)) / (x.std(0) + 1e-3)

    return np.concatenate([z(rel), ALIGN_SPEED_WEIGHT * z(vel)], axis=1)


def align(
    content: Take, target: Take, features: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray | None:
    """For each frame of ``content`` the (fractional) frame of ``target`` performing the same
    moment: subsequence dynamic time warping (librosa) with the target running 0.5 to 2
    times as fast as the content; ``None`` where no such path exists (the target too
    short). ``features``: both takes' :func:`alignment_features`, if already computed."""
    from librosa.sequence import dtw

    if target.frames * 2 < content.frames:
        return None
    a, b = features or (alignment_features(content), alignment_features(target))
    cost, path = dtw(
        a.T,
        b.T,
        metric="euclidean",
        step_sizes_sigma=SLOPES,
        subseq=True,
    )
    if not np.isfinite(cost[-1]).any():
        return None
    path = path[::-1]
    frames = np.arange(content.frames)
    return np.interp(frames, path[:, 0], path[:, 1])


def at_frames(x: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """``x (F, C)`` linearly interpolated at fractional ``frames``."""
    lo = np.clip(np.floor(frames).astype(np.int64), 0, len(x) - 1)
    hi = np.minimum(lo + 1, len(x) - 1)
    w = (frames - lo)[:, None].astype(np.float32)
    return (1 - w) * x[lo] + w * x[hi]


class Pairs:
    """Draws supervised examples: content windows, the target's rotations and positions at
    the aligned frames, and where its style code comes from."""

    def __init__(
        self,
        takes: list[Take],
        window: int,
        rng: np.random.Generator,
        contents: set[str] | None = None,
    ) -> None:
        """``contents``: the names of the takes that content windows come from (all)."""
        self.window = window
        self.rng = rng
        self.takes = [t for t in takes if t.frames >= window]
        self.by_style: dict[int, list[Take]] = {}
        self.by_action: dict[tuple[str, bool], list[Take]] = {}
        self.by_style_action: dict[tuple[int, str, bool], list[Take]] = {}
        for t in self.takes:
            self.by_style.setdefault(t.style, []).append(t)
            if contents is None or t.name in contents:
                self.by_action.setdefault((t.label, t.mirrored), []).append(t)
            self.by_style_action.setdefault((t.style, t.label, t.mirrored), []).append(t)
        self.styles = sorted(self.by_style)
        self.actions_of = {
            s: sorted({(t.label, t.mirrored) for t in self.by_style[s]} & set(self.by_action))
            for s in self.styles
        }
        # styles a pair can be drawn for (a validation set may lack some styles' actions)
        self.drawable = [s for s in self.styles if self.actions_of[s]]
        self.alignments: dict[tuple[str, str], np.ndarray | None] = {}
        self._features: dict[str, np.ndarray] = {}

    def aligned(self, a: Take, b: Take) -> np.ndarray | None:
        key = (a.name, b.name)
        if key not in self.alignments:
            for t in (a, b):
                if t.name not in self._features:
                    self._features[t.name] = alignment_features(t)
            features = self._features[a.name], self._features[b.name]
            self.alignments[key] = align(a, b, features)
        return self.alignments[key]

    def every_pair(self) -> list[tuple[Take, Take]]:
        """Every (content, target) pair :meth:`draw_pair` may draw, but a take with itself."""
        return [
            (a, b)
            for (label, flipped), contents in self.by_action.items()
            for a in contents
            for style in self.styles
            for b in self.by_style_action.get((style, label, flipped), [])
            if a is not b
        ]

    def _start(self, take: Take) -> int:
        return int(self.rng.integers(0, take.frames - self.window + 1))

    def draw_pair(self) -> tuple[Take, int, Take, np.ndarray]:
        """A content take, the start of its window, a take of the same action in a random
        style (the content's own style too, then maybe the same take) and the frames of it
        aligned with the window."""
        while True:
            style = self.drawable[self.rng.integers(len(self.drawable))]
            label, flipped = self.actions_of[style][self.rng.integers(len(self.actions_of[style]))]
            contents = self.by_action[label, flipped]
            targets = self.by_style_action[style, label, flipped]
            a = contents[self.rng.integers(len(contents))]
            b = targets[self.rng.integers(len(targets))]
            frames = np.arange(a.frames, dtype=np.float64) if a is b else self.aligned(a, b)
            if frames is not None:
                start = self._start(a)
                return a, start, b, frames[start : start + self.window]

    def style_window(self, style: int, length: int) -> tuple[Take, int]:
        """A random window of ``length`` frames (whole take if shorter) of a take of
        ``style``."""
        pool = self.by_style[style]
        take = pool[self.rng.integers(len(pool))]
        return take, int(self.rng.integers(0, max(take.frames - length, 0) + 1))


def window_of(x: np.ndarray, start: int, length: int) -> np.ndarray:
    """``x[start:start + length]``, edge-padded to ``length`` frames where the take ends."""
    w = x[start : start + length]
    if len(w) < length:
        w = np.concatenate([w, np.repeat(w[-1:], length - len(w), axis=0)])
    return w


def save_alignments(path, alignments: dict[tuple[str, str], np.ndarray | None]) -> None:
    """Computed alignments as one ``.npz`` (``None`` stored as an empty array)."""
    import json

    keys = sorted(alignments)
    values = [np.zeros(0) if alignments[k] is None else alignments[k] for k in keys]
    save_npz(  # two trainings at once may both save
        path,
        keys=np.array(json.dumps(keys)),
        lengths=np.array([len(v) for v in values]),
        frames=np.concatenate(values).astype(np.float32) if values else np.zeros(0),
    )


def load_alignments(path) -> dict[tuple[str, str], np.ndarray | None]:
    import json

    with np.load(path) as z:
        keys = [tuple(k) for k in json.loads(str(z["keys"]))]
        bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
        frames = z["frames"].astype(np.float64)
    return {
        k: (frames[a:b] if b > a else None)
        for k, a, b in zip(keys, bounds[:-1], bounds[1:], strict=True)
    }

"""What the foreign evaluation (``training.eval_foreign``) measures without a classifier: how
much of the content an output keeps, how far apart the styles of one item lie, and whether
its limbs move as a body can (:class:`Limbs`), against real Bandai mocap."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion import anatomy
from motion import canonical as C
from motion import features as Fe
from motion import kinematics as K
from motion import rotations as rot
from motion.skeleton import Motion
from motion.styles import canonical_style
from training.judges import skating

EFFECTORS = [C.INDEX[n] for n in ("Hand_L", "Hand_R", "Foot_L", "Foot_R")]
KEPT = 0.85  # content-kept correlation counted as kept


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


@dataclass(frozen=True)
class Limbs:
    """What the anatomy figures need of a clip (:mod:`motion.anatomy`): its frames, those
    with a knee bent backwards, those with an elbow bent backwards, and its fastest joint
    (body heights a second)."""

    frames: int
    backwards: int
    elbows_backwards: int
    peak_speed: float

    @staticmethod
    def of(motion: Motion) -> Limbs:
        return Limbs(
            motion.num_frames,
            int(anatomy.knees_backwards(motion).sum()),
            int(anatomy.elbows_backwards(motion).sum()),
            anatomy.peak_speed(motion),
        )


def limb_figures(limbs: list[Limbs]) -> dict:
    """Knees and elbows bent backwards (share of all frames, the worst clip's share) and
    the fastest joint (the fastest clip's, and the 99th percentile of the clips' fastest)."""
    frames = max(sum(x.frames for x in limbs), 1)
    return {
        "knees_backwards": round(sum(x.backwards for x in limbs) / frames, 5),
        "knees_backwards_worst_clip": round(max(x.backwards / x.frames for x in limbs), 4),
        "elbows_backwards": round(sum(x.elbows_backwards for x in limbs) / frames, 5),
        "elbows_backwards_worst_clip": round(max(x.elbows_backwards / x.frames for x in limbs), 4),
        "peak_speed_bh_s": round(max(x.peak_speed for x in limbs), 2),
        "peak_speed_p99_bh_s": round(float(np.percentile([x.peak_speed for x in limbs], 99)), 2),
    }


@dataclass
class RealBandai:
    """What the spread and the foot sliding compare with: the descriptors' standardisation,
    the real spread (overall and per dataset), real mocap's foot sliding and its limbs'
    figures (:func:`limb_figures`)."""

    mean: np.ndarray
    std: np.ndarray
    spread: float
    spread_by_dataset: dict[str, float]
    sliding: float
    anatomy: dict

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
        limb_figures([Limbs.of(c.motion) for c in clips]),
    )

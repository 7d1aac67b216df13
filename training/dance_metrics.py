"""The dance-generation papers' measures of how near generated dances are to real ones,
computed on canonical motion (numpy and scipy only).

- :func:`kinetic_features` and :func:`geometric_features`: the AIST++ features (Li et al.
  2021, "AI Choreographer"; the same code scores Bailando, Siyao et al. 2022): per joint the
  mean squared horizontal and vertical speed and the mean acceleration (velocities averaged
  over +-2 frames), and the frame-share of 32 boolean relational features of Mueller et al.
  2005 (hands above the head, knees bent, feet raised, fast hands...);
- :func:`frechet_distance`: the Frechet distance between two sets of feature vectors
  (FID_k, FID_g), after the papers' normalisation by a reference set's mean and std;
- :func:`diversity`: the mean pairwise Euclidean distance of a set's (normalised) features
  (Div_k, Div_g);
- :func:`feature_distances`: those distances per half and genre for ``make eval-dance``
  (:func:`distance_table` prints them);
- :func:`physical_foot_contact`: EDGE's physical foot contact score (Tseng et al. 2023):
  the hips' acceleration (upward acceleration kept, downward free fall not; divided by its
  peak in the clip) times the slower foot point's horizontal displacement of each foot,
  averaged over frames, x 10,000: a body that accelerates while neither foot is planted.

On the canonical skeleton: all 21 body joints (``joint_Root`` stays at the origin), positions
in metres, velocities per second at the motion's own frame rate. The papers' fairmotion code
divides the relational features' velocities by 1/120 s whatever the data's rate and fixes
the body sizes of one SMPL body; here the thresholds are Mueller's, in the canonical
skeleton's own humerus length, shoulder width and hip width per second.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import linalg

from motion import canonical as C
from motion import kinematics as K
from motion.skeleton import Motion

BODY = np.arange(1, len(C.JOINTS))
KINETIC_WINDOW = 2  # frames each side of the velocity and acceleration averages
EPS = 1e-10
STD_FLOOR = 1e-9  # a reference std at or under this: the feature is constant there


def body_positions(motion: Motion) -> np.ndarray:
    """``(T, 21, 3)`` global positions in metres of a canonical motion's body joints."""
    if motion.skeleton.names != C.JOINTS:
        raise ValueError("expected a motion on the canonical skeleton")
    return K.global_positions(motion)[:, BODY] / 100.0


def _window_mean(x: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Mean of ``x[first[i] : last[i] + 1]`` along axis 0 for each i (cumulative sums)."""
    cum = np.concatenate([np.zeros_like(x[:1]), np.cumsum(x, axis=0)])
    counts = (last - first + 1).reshape((-1,) + (1,) * (x.ndim - 1))
    return (cum[last + 1] - cum[first]) / counts


def kinetic_features(positions: np.ndarray, fps: float) -> np.ndarray:
    """``(3 J,)`` AIST++ kinetic features of ``(T, J, 3)`` positions (metres, y up): per
    joint, over frames 1..T-1, the mean of the squared horizontal and vertical speed of the
    displacement averaged over +-2 frames, and the mean norm of the acceleration averaged
    over the same window."""
    t = len(positions)
    if t < 3:
        return np.zeros(3 * positions.shape[1])
    dt = 1.0 / fps
    frames = np.arange(1, t)
    disp = np.diff(positions, axis=0)  # disp[k - 1] = p[k] - p[k - 1], k = 1..T-1
    lo = np.maximum(frames - KINETIC_WINDOW, 1)
    hi = np.minimum(frames + KINETIC_WINDOW, t - 1)
    velocity = _window_mean(disp, lo - 1, hi - 1) / dt  # (T-1, J, 3)
    horizontal = (velocity[..., [0, 2]] ** 2).sum(-1).mean(0)
    vertical = (velocity[..., 1] ** 2).mean(0)
    accel = np.diff(positions, n=2, axis=0) / dt**2  # accel[k - 1] at frame k = 1..T-2
    hi_a = np.minimum(frames + KINETIC_WINDOW, t - 2)
    expenditure = np.linalg.norm(_window_mean(accel, lo - 1, hi_a - 1), axis=-1).mean(0)
    return np.stack([horizontal, vertical, expenditure], axis=1).reshape(-1)


# Canonical joints under the names of the papers' relational features.
_NAMES = {
    "root": "Hips", "belly": "Spine", "chest": "Chest", "neck": "Neck", "head": "Head",
    "lhip": "UpperLeg_L", "lknee": "LowerLeg_L", "lankle": "Foot_L", "ltoes": "Toes_L",
    "rhip": "UpperLeg_R", "rknee": "LowerLeg_R", "rankle": "Foot_R", "rtoes": "Toes_R",
    "lshoulder": "UpperArm_L", "lelbow": "LowerArm_L", "lwrist": "Hand_L",
    "rshoulder": "UpperArm_R", "relbow": "LowerArm_R", "rwrist": "Hand_R",
}  # fmt: skip


def _rest_distance(a: str, b: str) -> float:
    rest = C.SKELETON.rest_positions() / 100.0
    return float(np.linalg.norm(rest[C.INDEX[_NAMES[a]]] - rest[C.INDEX[_NAMES[b]]]))


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a * b).sum(-1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), EPS)


def geometric_features(positions: np.ndarray, fps: float) -> np.ndarray:
    """``(32,)`` the share of frames 1..T-1 in which each of the AIST++ relational features
    holds, for ``(T, 21, 3)`` canonical body positions (metres, y up)."""
    if len(positions) < 2:
        return np.zeros(32)
    gpos = np.zeros((len(positions), len(C.JOINTS), 3))
    gpos[:, BODY] = positions
    hl = _rest_distance("lshoulder", "lelbow")  # humerus length
    sw = _rest_distance("lshoulder", "rshoulder")
    hw = _rest_distance("lhip", "rhip")
    now = {k: gpos[1:, C.INDEX[v]] for k, v in _NAMES.items()}
    prev = {k: gpos[:-1, C.INDEX[v]] for k, v in _NAMES.items()}
    frames = len(positions) - 1
    up = np.broadcast_to([0.0, 1.0, 0.0], (frames, 3))
    zero = np.zeros((frames, 3))
    floor = np.zeros((frames, 3))
    floor[:, 1] = positions[1:, :, 1].min(axis=1)
    now.update(up=up, down=-up, zero=zero, floor=floor)

    def move(j1, j2, j3, j4, threshold):
        # velocity of j3 relative to j1 along the direction j1 -> j2 (the papers' code
        # moves j3, not j4: kept, so that the features are theirs)
        velocity = (now[j3] - now[j1] - (prev[j3] - prev[j1])) * fps
        return _dot(velocity, _unit(now[j2] - now[j1])) > threshold

    def nmove(j1, j2, j3, j4, threshold):
        # velocity of j4 relative to j1 along the normal of the plane (j1, j2, j3)
        velocity = (now[j4] - now[j1] - (prev[j4] - prev[j1])) * fps
        normal = np.cross(now[j3] - now[j1], now[j2] - now[j1])
        return _dot(velocity, _unit(normal)) > threshold

    def plane(j1, j2, j3, p, threshold):
        normal = np.cross(now[j3] - now[j1], now[j2] - now[j1])
        return _dot(_unit(normal), now[p] - now[j1]) > threshold

    def nplane(n1, n2, a, p, threshold):
        return _dot(_unit(now[n2] - now[n1]), now[p] - now[a]) > threshold

    def angle(j1, j2, k1, k2, low, high):
        cos = _dot(_unit(now[j2] - now[j1]), _unit(now[k2] - now[k1]))
        degrees = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        return (degrees > low) & (degrees < high)

    def fast(j, threshold):
        return np.linalg.norm(now[j] - prev[j], axis=-1) * fps > threshold

    features = [
        nmove("neck", "rhip", "lhip", "rwrist", 1.8 * hl),
        nmove("neck", "lhip", "rhip", "lwrist", 1.8 * hl),
        nplane("chest", "neck", "neck", "rwrist", 0.2 * hl),
        nplane("chest", "neck", "neck", "lwrist", 0.2 * hl),
        move("belly", "chest", "chest", "rwrist", 1.8 * hl),
        move("belly", "chest", "chest", "lwrist", 1.8 * hl),
        angle("relbow", "rshoulder", "relbow", "rwrist", 0, 110),
        angle("lelbow", "lshoulder", "lelbow", "lwrist", 0, 110),
        nplane("lshoulder", "rshoulder", "lwrist", "rwrist", 2.5 * sw),
        move("lwrist", "rwrist", "rwrist", "lwrist", 1.4 * hl),
        move("rwrist", "root", "lwrist", "root", 1.4 * hl),
        move("lwrist", "root", "rwrist", "root", 1.4 * hl),
        fast("rwrist", 2.5 * hl),
        fast("lwrist", 2.5 * hl),
        plane("root", "lhip", "ltoes", "rankle", 0.38 * hl),
        plane("root", "rhip", "rtoes", "lankle", 0.38 * hl),
        nplane("zero", "up", "floor", "rankle", 1.2 * hl),
        nplane("zero", "up", "floor", "lankle", 1.2 * hl),
        nplane("lhip", "rhip", "lankle", "rankle", 2.1 * hw),
        angle("rknee", "rhip", "rknee", "rankle", 0, 110),
        angle("lknee", "lhip", "lknee", "lankle", 0, 110),
        fast("rankle", 2.5 * hl),
        fast("lankle", 2.5 * hl),
        angle("neck", "root", "rshoulder", "relbow", 25, 180),
        angle("neck", "root", "lshoulder", "lelbow", 25, 180),
        angle("neck", "root", "rhip", "rknee", 50, 180),
        angle("neck", "root", "lhip", "lknee", 50, 180),
        plane("rankle", "neck", "lankle", "root", 0.5 * hl),
        angle("neck", "root", "zero", "up", 70, 110),
        nplane("zero", "down", "floor", "rwrist", -1.2 * hl),
        nplane("zero", "down", "floor", "lwrist", -1.2 * hl),
        fast("root", 2.3 * hl),
    ]
    return np.stack(features, axis=1).mean(axis=0).astype(np.float64)


def segments(motion: Motion, seconds: float, start: int = 0, stop: int | None = None):
    """Whole non-overlapping pieces of ``seconds`` of ``motion[start:stop]``: ``(first
    frame, piece)`` pairs."""
    length = int(round(seconds * motion.fps))
    stop = motion.num_frames if stop is None else min(stop, motion.num_frames)
    return [(s, motion.slice(s, s + length)) for s in range(start, stop - length + 1, length)]


FEATURES = ("kinetic", "geometric")
KINETIC_NAMES = tuple(f"{C.JOINTS[j]} {kind}" for j in BODY
                      for kind in ("horizontal speed²", "vertical speed²", "acceleration"))  # fmt: skip
GEOMETRIC_NAMES = (
    "right hand moves forward", "left hand moves forward", "right hand above neck",
    "left hand above neck", "right hand moves up", "left hand moves up", "right elbow bent",
    "left elbow bent", "hands apart", "hands approach", "right hand moves from root",
    "left hand moves from root", "right hand fast", "left hand fast", "right foot in front",
    "left foot in front", "right foot raised", "left foot raised", "feet apart",
    "right knee bent", "left knee bent", "right foot fast", "left foot fast", "right arm out",
    "left arm out", "right leg out", "left leg out", "root behind the feet", "spine horizontal",
    "right hand low", "left hand low", "root fast",
)  # fmt: skip
"""Names of :func:`kinetic_features`' and :func:`geometric_features`' values, in order."""
GAPS = 3  # the largest feature gaps each distance row reports


def feature_gaps(generated: np.ndarray, real: np.ndarray, top: int = GAPS) -> list[int]:
    """Indices of the ``top`` features that hold a generated set furthest from a real one:
    the largest terms ``(mean(generated) - mean(real))^2`` of the Frechet distance's mean
    part (on normalised features, the distance's own units), largest first."""
    generated, real = np.asarray(generated, np.float64), np.asarray(real, np.float64)
    term = (generated.mean(axis=0) - real.mean(axis=0)) ** 2
    return [int(i) for i in np.argsort(-term)[:top]]


def dance_features(motion: Motion) -> dict[str, np.ndarray]:
    """``{"kinetic": (63,), "geometric": (32,)}`` of one canonical piece of dance."""
    pos = body_positions(motion)
    return {
        "kinetic": kinetic_features(pos, motion.fps),
        "geometric": geometric_features(pos, motion.fps),
    }


class Normaliser:
    """The papers' normalisation: each feature less the reference set's mean, over its std;
    a feature the reference never varies (a relation no real piece shows: root in front of
    the ankles' and neck's plane) is only centred, not divided by ``EPS``: one generated
    waltz piece holding it in 3 % of its frames had made the waltz's FID_g 10^14."""

    def __init__(self, reference: np.ndarray) -> None:
        reference = np.asarray(reference, dtype=np.float64)
        self.mean = reference.mean(axis=0)
        std = reference.std(axis=0)
        self.std = np.where(std > STD_FLOOR, std, 1.0)

    def __call__(self, features: np.ndarray) -> np.ndarray:
        return (np.asarray(features, dtype=np.float64) - self.mean) / self.std


def frechet_terms(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The two parts of the Frechet distance between Gaussians fitted to the rows of ``a``
    and ``b``: where they lie, ``|mu_a - mu_b|^2``, and how they spread,
    ``tr(S_a + S_b - 2 (S_a S_b)^(1/2))`` (each set needs two rows). A generator whose pieces
    all look alike has a large spread part however well its mean matches."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if len(a) < 2 or len(b) < 2:
        raise ValueError("a Frechet distance needs at least two feature vectors a set")
    diff = a.mean(axis=0) - b.mean(axis=0)
    sa, sb = np.atleast_2d(np.cov(a, rowvar=False)), np.atleast_2d(np.cov(b, rowvar=False))
    with warnings.catch_warnings():  # fewer vectors than features: singular, as expected
        warnings.simplefilter("ignore", linalg.LinAlgWarning)
        covmean = linalg.sqrtm(sa @ sb)
        if not np.isfinite(covmean).all():
            offset = np.eye(len(sa)) * 1e-6
            covmean = linalg.sqrtm((sa + offset) @ (sb + offset))
    covmean = np.real(covmean)
    spread = np.trace(sa) + np.trace(sb) - 2.0 * np.trace(covmean)
    return float(diff @ diff), float(max(spread, 0.0))


def frechet_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Frechet distance between Gaussians fitted to the rows of ``a`` and ``b``:
    ``|mu_a - mu_b|^2 + tr(S_a + S_b - 2 (S_a S_b)^(1/2))`` (:func:`frechet_terms`)."""
    return float(sum(frechet_terms(a, b)))


def diversity(features: np.ndarray) -> float:
    """Mean Euclidean distance between every two rows of ``features``."""
    x = np.asarray(features, dtype=np.float64)
    if len(x) < 2:
        return float("nan")
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    return float(d[np.triu_indices(len(x), 1)].mean())


PFC_SECONDS = 5.0  # EDGE scores 5-s dances; the score divides by the clip's peak acceleration


def physical_foot_contact(motion: Motion, seconds: float = PFC_SECONDS) -> float:
    """EDGE's physical foot contact score of a canonical motion (lower is better), averaged
    over its whole pieces of ``seconds`` (the motion whole when shorter)."""
    pieces = [p for _, p in segments(motion, seconds)] or [motion]
    return float(np.mean([_pfc(p) for p in pieces]))


_FEET = [[C.INDEX["Foot_L"], C.INDEX["Toes_L"]], [C.INDEX["Foot_R"], C.INDEX["Toes_R"]]]


def _pfc(motion: Motion) -> float:
    gpos = K.global_positions(motion) / 100.0
    if len(gpos) < 3:
        return 0.0
    dt = 1.0 / motion.fps
    hips = gpos[:, C.INDEX["Hips"]]
    accel = np.diff(hips, n=2, axis=0) / dt**2
    accel[:, 1] = np.maximum(accel[:, 1], 0.0)  # falling is free; rising needs a push
    accel = np.linalg.norm(accel, axis=-1)
    peak = accel.max()
    if peak <= 0:
        return 0.0
    slowest = []
    for foot in _FEET:
        step = np.linalg.norm(np.diff(gpos[1:, foot][..., [0, 2]], axis=0), axis=-1)
        slowest.append(step.min(axis=1))
    return float((slowest[0] * slowest[1] * accel / peak).mean() * 10_000)


def matched_frechet_terms(
    candidate: np.ndarray, reference: np.ndarray, size: int, draws: int = 20, seed: int = 0
) -> tuple[float, float]:
    """:func:`frechet_terms` of ``size`` rows of ``candidate`` to ``reference``, averaged
    over ``draws`` random choices of the rows (one when ``candidate`` has ``size``): the
    distance of a few samples grows as their number falls, so two candidates are compared
    at one size."""
    candidate = np.asarray(candidate, dtype=np.float64)
    if size >= len(candidate):
        return frechet_terms(candidate, reference)
    rng = np.random.default_rng(seed)
    picks = [rng.choice(len(candidate), size, replace=False) for _ in range(draws)]
    terms = np.array([frechet_terms(candidate[p], reference) for p in picks])
    return float(terms[:, 0].mean()), float(terms[:, 1].mean())


def matched_frechet(
    candidate: np.ndarray, reference: np.ndarray, size: int, draws: int = 20, seed: int = 0
) -> float:
    """The Frechet distance of :func:`matched_frechet_terms`."""
    return float(sum(matched_frechet_terms(candidate, reference, size, draws, seed)))


SEGMENT_SECONDS = 5.0  # the pieces whose features the distances compare
HALVES = ("dev", "test")


def _features(pieces: list[Motion]) -> dict[str, np.ndarray]:
    rows = [dance_features(p) for p in pieces]
    return {k: np.array([r[k] for r in rows]).reshape(len(rows), -1) for k in FEATURES}


def feature_distances(held: list, train: list, generated: dict[str, list[Motion]]) -> dict:
    """AIST++ kinetic and geometric feature distances per half and genre.

    Pieces of ``SEGMENT_SECONDS``: of the real dance of each held-out song (the reference),
    of the dances generated for it in its own genre (every seed), and of the real dances of
    the training songs of that genre (the real-vs-real baseline: other songs). The
    development half is the first half of each held-out song, the test half the second.
    Features are normalised by the mean and std of every real piece of every song, the
    generated and the other songs' sets compared to the reference at one size (the smaller
    one's, ``matched_frechet``); diversity is the mean distance between a set's pieces.
    """
    genres = sorted({h[1] for h in held})
    pieces = {half: {g: {"real": [], "generated": []} for g in genres} for half in HALVES}
    for name, genre, real, _, _ in held:
        middle = real.num_frames // 2
        for half, (start, stop) in zip(HALVES, ((0, middle), (middle, None)), strict=True):
            cut = pieces[half][genre]
            cut["real"] += [p for _, p in segments(real, SEGMENT_SECONDS, start, stop)]
            for out in generated.get(name, []):
                cut["generated"] += [p for _, p in segments(out, SEGMENT_SECONDS, start, stop)]
    others = {g: [p for genre, m in train if genre == g
                  for _, p in segments(m, SEGMENT_SECONDS)] for g in genres}  # fmt: skip
    other_features = {g: _features(v) for g, v in others.items()}
    every_real = [p for half in pieces.values() for g in half.values() for p in g["real"]]
    everything = _features(every_real + [p for v in others.values() for p in v])
    normalise = {k: Normaliser(everything[k]) for k in FEATURES}
    report: dict = {"segment_seconds": SEGMENT_SECONDS}
    for half, by_genre in pieces.items():
        rows = {}
        pooled: dict[str, list] = {"real": [], "generated": [], "other_songs": []}
        for genre, sets in by_genre.items():
            feats = {
                "real": _features(sets["real"]),
                "generated": _features(sets["generated"]),
                "other_songs": other_features[genre],
            }
            for key in pooled:
                pooled[key].append(feats[key])
            rows[genre] = _distance_row(feats, normalise)
        merged = {k: {f: np.concatenate([x[f] for x in v]) for f in FEATURES}
                  for k, v in pooled.items()}  # fmt: skip
        rows["all"] = _distance_row(merged, normalise)
        report[half] = rows
    return report


def _distance_row(feats: dict[str, dict[str, np.ndarray]], normalise: dict) -> dict:
    counts = {k: len(v["kinetic"]) for k, v in feats.items()}
    size = min(counts["generated"], counts["other_songs"])
    row: dict = {"pieces": counts}
    for kind in FEATURES:
        real, gen, other = (normalise[kind](feats[k][kind])
                            for k in ("real", "generated", "other_songs"))  # fmt: skip
        generated_terms = matched_frechet_terms(gen, real, size)
        to_generated = sum(generated_terms)
        to_other = matched_frechet(other, real, size)
        row[kind] = {
            "generated_to_real": round(to_generated, 2),
            "generated_spread_share": round(generated_terms[1] / max(to_generated, 1e-9), 3),
            "other_songs_to_real": round(to_other, 2),
            "ratio": round(to_generated / max(to_other, 1e-9), 2),
            "diversity_generated": round(diversity(gen), 2),
            "diversity_real": round(diversity(real), 2),
            "diversity_other_songs": round(diversity(other), 2),
            "largest_gaps": [
                {
                    "feature": (KINETIC_NAMES if kind == "kinetic" else GEOMETRIC_NAMES)[i],
                    "term": round(float((gen[:, i].mean() - real[:, i].mean()) ** 2), 1),
                    "generated": round(float(feats["generated"][kind][:, i].mean()), 3),
                    "real": round(float(feats["real"][kind][:, i].mean()), 3),
                }
                for i in feature_gaps(gen, real)
            ],
        }
    return row


def distance_table(distances: dict) -> list[str]:
    lines = [
        f"Distance to real dance (AIST++ kinetic and geometric features of "
        f"{distances['segment_seconds']:g}-s pieces, normalised by every real piece): Frechet "
        "distance to the held-out songs' real dance of the dances generated for them, and of "
        "the real dances of the other songs of the genre (real vs real), at one number of "
        "pieces; the ratio of the two; diversity (mean distance between pieces) of the "
        "generated and of the real held-out dance. Development half: the first half of each "
        "song; test half: the second.",
        "",
        "| half | genre | pieces real / generated / other songs | FID_k generated / real vs "
        "real (ratio) | FID_g generated / real vs real (ratio) | Div_k generated / real | "
        "Div_g generated / real |",
        "|---|---|---|---|---|---|---|",
    ]
    for half in HALVES:
        for genre, row in distances[half].items():
            k, g, n = row["kinetic"], row["geometric"], row["pieces"]
            lines.append(
                f"| {half} | {genre} | {n['real']} / {n['generated']} / {n['other_songs']} | "
                f"{k['generated_to_real']:.1f} / {k['other_songs_to_real']:.1f} ({k['ratio']:.2f}) | "
                f"{g['generated_to_real']:.1f} / {g['other_songs_to_real']:.1f} ({g['ratio']:.2f}) | "
                f"{k['diversity_generated']:.1f} / {k['diversity_real']:.1f} | "
                f"{g['diversity_generated']:.1f} / {g['diversity_real']:.1f} |"
            )
    lines += ["", "The generated dances' distance by its parts: the spread's share (how differently "
              "the pieces vary; the rest is where they lie on average), then the largest gaps "
              "(a feature's term of the location part, normalised; generated / real means of "
              "the raw feature, m²/s², m/s² or share of frames):"]  # fmt: skip
    for half in HALVES:
        for genre, row in distances[half].items():
            for kind, label in (("kinetic", "FID_k"), ("geometric", "FID_g")):
                gaps, spread = row[kind]["largest_gaps"], row[kind]["generated_spread_share"]
                lines.append(
                    f"- {half} {genre} {label} (spread {spread:.0%}): "
                    + "; ".join(
                        f"{x['feature']} {x['term']:.1f} ({x['generated']:.3g} / {x['real']:.3g})"
                        for x in gaps
                    )
                )
    return lines

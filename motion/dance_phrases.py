"""A dance made of real phrases: a library of real dances with the music they were danced
to, and a sampler that joins phrases of the requested genre where the poses meet and the
music is alike (a motion graph with music matching, as ChoreoMaster, Chen et al. 2021).

The sampler works on standardised dance features and a per-frame music descriptor (the
dance network's audio code); what it returns takes the rolled-out poses' place in the
dance engine, so the low-pass, the standstills, the feet and the beat warp follow it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion import canonical as C
from motion import dance_features as DF
from motion import rotations as rot
from motion.grounding import pin_canonical_feet
from motion.skeleton import Motion

PHRASE = 120  # frames of each phrase (4 s at 30 fps): a few bars of any ballroom tempo
BLEND = 8  # frames of the cross-fade at a join
STRIDE = 4  # library frames between candidate phrase starts
MUSIC_STEP = 8  # frames between the music rows compared over a phrase
CHOICES = 8  # the seeded pick is among this many cheapest candidates
REUSE_FRAMES = 90 * DF.FPS  # a phrase is not danced twice within this many output frames
POSE = slice(0, DF.ROTATION_CHANNELS + 1)  # the body's rotations and the root's height
KEY = slice(0, DF.ROTATION_CHANNELS + DF.ROOT_CHANNELS)  # and the root's velocity and turn
HIPS = C.INDEX["Hips"]
PIN_MARGIN = 4  # frames either side of a cross-fade whose contacts the join pins


@dataclass
class PhraseLibrary:
    """Real dances, concatenated: standardised ``motion (N, M)``, the standardised ``music
    (N, D)`` descriptor they were danced to, each frame's ``genre`` and ``song`` index."""

    motion: np.ndarray
    music: np.ndarray
    genre: np.ndarray
    song: np.ndarray
    lrot: np.ndarray | None = None  # (N, J, 4): the dances themselves, on the canonical
    hips: np.ndarray | None = None  # (N, 3) skeleton, where a dance of phrases is joined
    usable: np.ndarray | None = None  # (N,) bool: frames a phrase may hold (default all)
    contacts: np.ndarray | None = None  # (N, 4): the takes' own foot contacts

    def candidates(self, genre: int) -> np.ndarray:
        """Phrase starts of ``genre``: every ``STRIDE`` frames, the phrase and its blend
        tail inside one song and on usable frames, two frames before the start for the
        pose and its change."""
        n = len(self.motion)
        starts = np.arange(2, n - PHRASE - BLEND, STRIDE)
        keep = (self.genre[starts] == genre) & (
            self.song[starts - 1] == self.song[starts + PHRASE + BLEND - 1]
        )
        if self.usable is not None:
            bad = np.concatenate([[0], np.cumsum(~np.asarray(self.usable, bool))])
            keep &= bad[starts + PHRASE + BLEND] == bad[starts - 2]
        return starts[keep]


def _music_windows(music: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """``(len(starts), PHRASE // MUSIC_STEP * D)``: the music rows over each phrase."""
    rows = starts[:, None] + np.arange(0, PHRASE, MUSIC_STEP)[None]
    return music[np.minimum(rows, len(music) - 1)].reshape(len(starts), -1)


def _pose_key(motion: np.ndarray, frame: np.ndarray, channels: slice = POSE) -> np.ndarray:
    """The pose at ``frame`` and its change from the frame before, to match a join."""
    now, before = motion[frame, channels], motion[frame - 1, channels]
    return np.concatenate([now, 2.0 * (now - before)], axis=-1)


class PhraseSampler:
    """Joins phrases of one library; the candidates' music windows are computed once per
    genre."""

    def __init__(self, library: PhraseLibrary, channels: slice = POSE) -> None:
        self.library = library
        self.channels = channels  # of the standardised features matched at a join
        self._genres: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _genre(self, genre: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if genre not in self._genres:
            starts = self.library.candidates(genre)
            if len(starts) == 0:
                raise ValueError(f"the phrase library has no dance of genre {DF.GENRES[genre]}")
            self._genres[genre] = (
                starts,
                _music_windows(self.library.music, starts),
                _pose_key(self.library.motion, starts - 1, self.channels),
            )
        return self._genres[genre]

    def dance(
        self, music: np.ndarray, genre: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """Standardised poses ``(F, M)`` for ``music (F, D)``, and the ``(output frame,
        library frame)`` of each phrase. Each join picks, among the ``CHOICES`` cheapest,
        a phrase whose first pose meets the dance's last and whose music is like the next
        ``PHRASE`` frames' (each cost over its median among the candidates)."""
        lib = self.library
        starts, windows, keys = self._genre(genre)
        frames = len(music)
        out = np.empty((frames + PHRASE + BLEND, lib.motion.shape[1]), np.float32)
        last_used = np.full(len(lib.motion), -(10**9), np.int64)
        joins: list[tuple[int, int]] = []
        t, source = 0, -1
        while t < frames:
            wanted = _music_windows(music, np.array([t]))[0]
            cost = ((windows - wanted) ** 2).mean(axis=1)
            cost = cost / max(float(np.median(cost)), 1e-9)
            if source >= 0:
                pose = ((keys - _pose_key(out, np.array([t - 1]), self.channels)[0]) ** 2).mean(
                    axis=1
                )
                cost = cost + pose / max(float(np.median(pose)), 1e-9)
            recent = (t - last_used[starts] < REUSE_FRAMES) | (
                t - last_used[starts + PHRASE - 1] < REUSE_FRAMES
            )
            if not recent.all():
                cost = np.where(recent, np.inf, cost)
            best = np.argsort(cost)[:CHOICES]
            start = int(starts[best[rng.integers(len(best))]])
            phrase = lib.motion[start : start + PHRASE + BLEND]
            if source >= 0:  # cross-fade the last phrase's continuation into this one
                fade = np.linspace(0.0, 1.0, BLEND + 2, dtype=np.float32)[1:-1, None]
                tail = lib.motion[source : source + BLEND]
                out[t : t + BLEND] = (1.0 - fade) * tail + fade * phrase[:BLEND]
                out[t + BLEND : t + PHRASE] = phrase[BLEND:PHRASE]
            else:
                out[t : t + PHRASE] = phrase[:PHRASE]
            last_used[start : start + PHRASE] = t
            joins.append((t, start))
            source = start + PHRASE  # where this phrase would go on, for the next fade
            t += PHRASE
        return out[:frames], joins


def _yaw_angle(q: np.ndarray) -> np.ndarray:
    fwd = rot.apply(q, np.array([0.0, 0.0, 1.0]))
    return np.arctan2(fwd[..., 0], fwd[..., 2])


def _placed(lib: PhraseLibrary, first: int, stop: int, at: tuple[np.ndarray, float]):
    """Library frames ``first:stop`` turned about +Y and moved on the floor so that frame
    ``first``'s hips stand at ``at`` = (position on the floor (3,), heading radians)."""
    lrot = lib.lrot[first:stop].astype(np.float64)
    hips = lib.hips[first:stop].astype(np.float64)
    turn = at[1] - float(_yaw_angle(lrot[0, HIPS]))
    spin = rot.about_y(np.array(turn))
    lrot[:, HIPS] = rot.mul(spin[None], lrot[:, HIPS])
    floor = hips[0] * np.array([1.0, 0.0, 1.0])
    hips = rot.apply(spin[None], hips - floor) + at[0]
    return lrot, hips


def _where(lrot: np.ndarray, hips: np.ndarray) -> tuple[np.ndarray, float]:
    return hips * np.array([1.0, 0.0, 1.0]), float(_yaw_angle(lrot[HIPS]))


def _runs_near_joins(contacts: np.ndarray, joins: list[tuple[int, int]]) -> np.ndarray:
    """``contacts (F, n)`` kept only in the runs that overlap a cross-fade or the
    ``PIN_MARGIN`` frames either side of it, each run whole."""
    frames = len(contacts)
    near = np.zeros(frames, bool)
    for t, _ in joins[1:]:
        near[max(0, t - PIN_MARGIN) : min(frames, t + BLEND + PIN_MARGIN)] = True
    kept = np.zeros_like(contacts, dtype=bool)
    for i in range(contacts.shape[1]):
        edges = np.flatnonzero(np.diff(np.concatenate([[0], contacts[:, i].astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if near[a:b].any():
                kept[a:b, i] = True
    return kept


def dance_motion(
    sampler: PhraseSampler,
    music: np.ndarray,
    genre: int,
    rng: np.random.Generator,
    pin_joins: bool = False,
) -> tuple[Motion, list[tuple[int, int]]]:
    """The phrases :meth:`PhraseSampler.dance` chooses, joined on the dancers' own motion
    (not its features, whose decoding slides the feet): each phrase turned and moved to
    start where the last one would have gone on, and cross-faded from that continuation
    over ``BLEND`` frames (rotations slerped, the hips' position mixed). With
    ``pin_joins`` the contacts the source takes hold across each join (both sources'
    during the fade) are pinned by leg IK, each contact run that reaches within
    ``PIN_MARGIN`` frames of a fade, and nothing else."""
    lib = sampler.library
    _, joins = sampler.dance(music, genre, rng)
    frames = len(music)
    lrot = np.empty((frames + PHRASE + BLEND, len(C.JOINTS), 4))
    hips = np.empty((frames + PHRASE + BLEND, 3))
    contacts = np.zeros((frames + PHRASE + BLEND, 4), bool)
    at = (np.zeros(3), 0.0)
    for k, (t, start) in enumerate(joins):
        r, h = _placed(lib, start, start + PHRASE + BLEND, at)
        if pin_joins:
            own = lib.contacts[start : start + PHRASE + BLEND]
            if k:  # a foot is planted across the fade where both sources plant it
                contacts[t : t + BLEND] &= own[:BLEND]
                contacts[t + BLEND : t + PHRASE + BLEND] = own[BLEND:]
            else:
                contacts[t : t + PHRASE + BLEND] = own
        if k:  # the last phrase's continuation, already written at t..t+BLEND
            fade = np.linspace(0.0, 1.0, BLEND + 2)[1:-1]
            lrot[t : t + BLEND] = rot.slerp(lrot[t : t + BLEND], r[:BLEND], fade[:, None])
            hips[t : t + BLEND] = (1 - fade[:, None]) * hips[t : t + BLEND] + fade[:, None] * h[
                :BLEND
            ]
            lrot[t + BLEND : t + PHRASE + BLEND] = r[BLEND:]
            hips[t + BLEND : t + PHRASE + BLEND] = h[BLEND:]
        else:
            lrot[t : t + PHRASE + BLEND], hips[t : t + PHRASE + BLEND] = r, h
        at = _where(r[PHRASE], h[PHRASE])  # the continuation's frame: the next phrase's start
    lpos = np.broadcast_to(C.SKELETON.offsets, (frames, len(C.JOINTS), 3)).copy()
    lpos[:, HIPS] = hips[:frames]
    motion = Motion(C.SKELETON, DF.FPS, rot.normalize(lrot[:frames]), lpos)
    if pin_joins:
        pinned = _runs_near_joins(contacts[:frames], joins)
        if pinned.any():
            motion = pin_canonical_feet(motion, pinned, hold_height=False)
    return motion, joins

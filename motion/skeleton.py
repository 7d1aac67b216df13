"""``Skeleton`` (topology, rest offsets, BVH channel layout) and ``Motion`` (a clip on it).

Arrays, not objects: a skeleton is ``names``, ``parents (J,)`` with
``parents[j] < j`` (root has -1), ``offsets (J, 3)``; a motion is local
rotations ``lrot (F, J, 4)`` (quaternions x, y, z, w) and local translations
``lpos (F, J, 3)``. ``lpos`` holds a joint's position channels where it has
them and its rest offset elsewhere, so one array covers a root-only layout
(CMU) and position channels on every joint (Bandai) alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from motion.errors import MotionError

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy with rest offsets and, for BVH, each joint's channel list.

    ``end_sites`` maps a joint index to the offsets of its End Site children
    (kept so that files round-trip; they carry no motion).
    """

    names: tuple[str, ...]
    parents: np.ndarray  # (J,) int, parents[j] < j, root -1
    offsets: np.ndarray  # (J, 3)
    channels: tuple[tuple[str, ...], ...] = ()
    end_sites: dict[int, tuple[tuple[float, float, float], ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "names", tuple(self.names))
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3):
            raise MotionError("skeleton arrays disagree on the number of joints")
        if n == 0:
            raise MotionError("skeleton has no joints")
        if any(p >= j for j, p in enumerate(parents)) or parents[0] != -1:
            raise MotionError("skeleton joints must be ordered parents first")
        if not self.channels:
            chans = (
                ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
            )
            chans += (("Zrotation", "Yrotation", "Xrotation"),) * (n - 1)
            object.__setattr__(self, "channels", chans)
        if len(self.channels) != n:
            raise MotionError("skeleton channel layout does not cover every joint")

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise MotionError(f"no joint named {name!r} in the skeleton", kind="unusable") from None

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.nonzero(self.parents == j)[0]]

    def has_position(self, j: int) -> bool:
        return any(c in POSITION_CHANNELS for c in self.channels[j])

    def rotation_order(self, j: int) -> str:
        """The joint's Euler order as channel letters, e.g. ``"ZXY"`` (``"ZYX"`` if none)."""
        order = "".join(c[0].upper() for c in self.channels[j] if c in ROTATION_CHANNELS)
        return order if len(order) == 3 else "ZYX"

    def bone_lengths(self) -> np.ndarray:
        """Length of the bone from each joint's parent to it, ``(J,)`` (root: 0)."""
        out = np.linalg.norm(self.offsets, axis=-1)
        out[0] = 0.0
        return out

    def rest_positions(self) -> np.ndarray:
        """Global joint positions ``(J, 3)`` in the rest pose (all rotations identity)."""
        pos = np.zeros((self.num_joints, 3))
        for j in range(1, self.num_joints):
            pos[j] = pos[self.parents[j]] + self.offsets[j]
        return pos

    def height(self) -> float:
        """Rough standing height: extent of the rest pose along its longest axis."""
        rest = self.rest_positions()
        ext = rest.max(axis=0) - rest.min(axis=0)
        return float(max(ext.max(), 1e-6))

    def with_offsets(self, offsets: np.ndarray) -> Skeleton:
        return replace(self, offsets=np.asarray(offsets, dtype=np.float64))


@dataclass(frozen=True, eq=False)
class Motion:
    """A clip: a skeleton, a frame rate, local rotations and local translations."""

    skeleton: Skeleton
    fps: float
    lrot: np.ndarray  # (F, J, 4) quaternions (x, y, z, w)
    lpos: np.ndarray  # (F, J, 3)

    def __post_init__(self) -> None:
        lrot = np.asarray(self.lrot, dtype=np.float64)
        lpos = np.asarray(self.lpos, dtype=np.float64)
        object.__setattr__(self, "lrot", lrot)
        object.__setattr__(self, "lpos", lpos)
        j = self.skeleton.num_joints
        if lrot.ndim != 3 or lrot.shape[1:] != (j, 4):
            raise MotionError(f"rotations must be (frames, {j}, 4), got {lrot.shape}")
        if lpos.shape != lrot.shape[:2] + (3,):
            raise MotionError(f"translations must be (frames, {j}, 3), got {lpos.shape}")
        if not np.isfinite(self.fps) or self.fps <= 0:
            raise MotionError(f"frame rate must be positive, got {self.fps}")

    @property
    def num_frames(self) -> int:
        return int(self.lrot.shape[0])

    @property
    def duration(self) -> float:
        return self.num_frames / self.fps

    @property
    def root_pos(self) -> np.ndarray:
        """Root translation ``(F, 3)``."""
        return self.lpos[:, 0]

    @staticmethod
    def from_root(skeleton: Skeleton, fps: float, lrot: np.ndarray, root_pos: np.ndarray) -> Motion:
        """A motion whose only moving translation is the root's (offsets elsewhere)."""
        lrot = np.asarray(lrot, dtype=np.float64)
        lpos = np.repeat(skeleton.offsets[None], lrot.shape[0], axis=0)
        lpos[:, 0] = root_pos
        return Motion(skeleton, float(fps), lrot, lpos)

    def replace(self, **changes) -> Motion:
        return replace(self, **changes)

    def slice(self, start: int, stop: int | None = None) -> Motion:
        """Frames ``start:stop`` as a new motion (arrays copied)."""
        return replace(self, lrot=self.lrot[start:stop].copy(), lpos=self.lpos[start:stop].copy())

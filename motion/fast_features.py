"""The fast style networks' motion encoding (holden2017), shared by training and serving.

Per frame (``F`` frames, canonical skeleton at 30 fps), in this channel order:

- ``POSITION_CHANNELS`` (63): the 21 body joints' positions (every canonical joint but
  ``joint_Root``, which never moves) relative to the root on the floor, in the facing
  frame (``kinematics.root_local``), x, y, z per joint. The root is the Hips projected
  onto the floor; the facing comes from hips and shoulders, smoothed.
- ``ROOT_CHANNELS`` (3): root velocity on the floor in the facing frame (sideways x,
  forward z; per second) and turning velocity (radians per second).
- ``CONTACT_CHANNELS`` (4): foot contacts of Foot_L, Toes_L, Foot_R, Toes_R
  (``motion.contacts``) as 0/1.

That is the paper's 66 degrees of freedom (21 x 3 + 3) plus the contact labels of its
lineage (Holden et al. 2016). Lengths are divided by the canonical leg length (``LEG``):
numbers are in leg lengths. Networks read standardised channels (``FastStats``: mean and
std per channel from the training data; positions share one std so distances keep their
proportions, contacts map to -1/+1), saved as ``.npz`` beside the model.

:func:`decode` inverts :func:`encode`: it integrates the root velocity and turning from a
start point and heading and puts the body back around it, giving global positions
``(F, 22, 3)`` (in canonical units) and the contacts.

Arrays are ``(F, CHANNELS)`` float32, frames first; networks read ``(batch, time, CHANNELS)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import canonical as C
from motion import contacts as CT
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion

FPS = C.FPS
LEG = C.leg_length()
HIPS = C.INDEX["Hips"]
BODY = np.arange(1, len(C.JOINTS))  # every joint but joint_Root
FACING_JOINTS = tuple(C.INDEX[n] for n in ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R"))
FACING_SMOOTH = 2.0  # Gaussian sigma in frames
FOOT_JOINTS = list(CT.CANONICAL_FOOT_JOINTS)  # Foot_L, Toes_L, Foot_R, Toes_R (canonical ids)

POSITION_CHANNELS = 3 * len(BODY)
ROOT_CHANNELS = 3
CONTACT_CHANNELS = len(FOOT_JOINTS)
CHANNELS = POSITION_CHANNELS + ROOT_CHANNELS + CONTACT_CHANNELS
VELOCITY = slice(POSITION_CHANNELS, POSITION_CHANNELS + 2)  # sideways, forward
TURN = POSITION_CHANNELS + 2
CONTACTS = slice(POSITION_CHANNELS + ROOT_CHANNELS, CHANNELS)


@dataclass(frozen=True)
class Encoded:
    """``features (F, CHANNELS)`` float32 and what decoding needs to land where the clip
    started: ``start (3,)`` the root on the floor at frame 0 (canonical units) and
    ``heading`` its facing angle about +Y (radians, +Z = 0)."""

    features: np.ndarray
    start: np.ndarray
    heading: float


def encode_positions(gpos: np.ndarray, fps: float = FPS) -> Encoded:
    """The encoding of global canonical positions ``gpos (F, 22, 3)`` (canonical units)."""
    gpos = np.asarray(gpos, dtype=np.float64)
    if gpos.ndim != 3 or gpos.shape[1:] != (len(C.JOINTS), 3) or len(gpos) == 0:
        raise MotionError(f"positions must be (frames, {len(C.JOINTS)}, 3), got {gpos.shape}")
    dirs = K.facing_directions(gpos, *FACING_JOINTS, smooth=FACING_SMOOTH)
    face = K.facing_rotations(dirs)
    root = gpos[:, HIPS] * np.array([1.0, 0.0, 1.0])
    local = K.root_local(gpos[:, BODY], root, face) / LEG
    vel, turn = K.root_velocities(root, face, fps)
    contacts = CT.foot_contacts(gpos, fps, FOOT_JOINTS, scale=LEG)
    features = np.concatenate(
        [local.reshape(len(gpos), -1), vel / LEG, turn[:, None], contacts.astype(np.float64)],
        axis=-1,
    )
    return Encoded(
        features=features.astype(np.float32),
        start=root[0].copy(),
        heading=float(np.arctan2(dirs[0, 0], dirs[0, 2])),
    )


def encode(motion: Motion) -> Encoded:
    """The encoding of a canonical motion at 30 fps (one forward-kinematics pass)."""
    C.check_motion(motion, "fast features")
    return encode_positions(K.global_positions(motion), motion.fps)


def decode(
    features: np.ndarray,
    start: np.ndarray | None = None,
    heading: float = 0.0,
    fps: float = FPS,
) -> tuple[np.ndarray, np.ndarray]:
    """Global positions ``(F, 22, 3)`` (canonical units) and contacts ``(F, 4)`` bool from
    raw (not standardised) features ``(F, CHANNELS)``.

    The root starts at ``start`` (on the floor; origin by default) facing ``heading``
    and moves by the features' velocities: the step from frame t to t + 1 is frame t's
    velocity, turned by frame t's heading. ``joint_Root`` stays at the origin, as on
    every canonical clip (the Hips carry the travel).
    """
    x = np.asarray(features, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != CHANNELS:
        raise MotionError(f"fast features must be (frames, {CHANNELS}), got {x.shape}")
    frames = len(x)
    root, face = K.integrate_root(x[:, VELOCITY] * LEG, x[:, TURN], fps, start, heading)
    local = x[:, :POSITION_CHANNELS].reshape(frames, len(BODY), 3) * LEG
    gpos = np.zeros((frames, len(C.JOINTS), 3))
    gpos[:, BODY] = rot.apply(face[:, None], local) + root[:, None]
    return gpos, x[:, CONTACTS] > 0.5


@dataclass(frozen=True)
class FastStats:
    """Per-channel ``mean`` and ``std`` ``(CHANNELS,)`` float32 of the raw features."""

    mean: np.ndarray
    std: np.ndarray

    @staticmethod
    def fit(features: list[np.ndarray]) -> FastStats:
        """Statistics of a list of ``(F_i, CHANNELS)`` arrays: per-channel means; one std
        shared by all position channels (their mean std), one per root channel; contacts
        fixed to mean 0.5, std 0.5 (so they read -1/+1)."""
        x = np.concatenate([np.asarray(f, dtype=np.float64) for f in features])
        mean = x.mean(axis=0)
        std = x.std(axis=0)
        std[:POSITION_CHANNELS] = std[:POSITION_CHANNELS].mean()
        mean[CONTACTS] = 0.5
        std[CONTACTS] = 0.5
        return FastStats(mean.astype(np.float32), np.maximum(std, 1e-4).astype(np.float32))

    def normalize(self, x: np.ndarray) -> np.ndarray:
        """Standardised features, same shape as ``x (..., CHANNELS)``, float32."""
        return ((np.asarray(x, dtype=np.float32) - self.mean) / self.std).astype(np.float32)

    def denormalize(self, z: np.ndarray) -> np.ndarray:
        """Raw features from standardised ``z (..., CHANNELS)``, float32."""
        return (np.asarray(z, dtype=np.float32) * self.std + self.mean).astype(np.float32)

    def save(self, path: str | Path) -> None:
        np.savez(path, mean=self.mean, std=self.std, channels=np.array(CHANNELS))

    @staticmethod
    def load(path: str | Path) -> FastStats:
        with np.load(path, allow_pickle=False) as z:
            if int(z["channels"]) != CHANNELS:
                raise MotionError(f"{path}: statistics for {int(z['channels'])} channels")
            return FastStats(z["mean"].astype(np.float32), z["std"].astype(np.float32))


def bone_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bones between body joints as indices into the 21 feature joints: ``child (B,)``,
    ``parent (B,)`` and the canonical length in leg lengths ``(B,)`` (Hips' own bone to
    the floor root is left out)."""
    child, parent, length = [], [], []
    for j in BODY[1:]:
        child.append(j - 1)
        parent.append(int(C.PARENTS[j]) - 1)
        length.append(float(np.linalg.norm(C.OFFSETS[j])) / LEG)
    return np.array(child), np.array(parent), np.array(length, dtype=np.float32)

"""The translator's encodings of a canonical motion (aberman2020), shared by training and serving.

Everything a translator network reads or writes is computed here once, in numpy, so the
PyTorch training code and the onnxruntime service see identical numbers. Inputs are
canonical ``Motion`` objects at 30 fps (``motion.canonical``); arrays are ``(F, C)``
float32, frames first (networks read ``(B, C, T)``: transpose and add a batch axis).

Glossary: ``F`` frames, ``lrot``/``grot`` local/global quaternions (x, y, z, w),
``gpos`` global positions, ``facing (F, 4)`` per-frame rotations about +Y that turn +Z
onto the body's facing direction, ``r6`` the continuous 6D rotation (two matrix columns).
Lengths are divided by the canonical leg length (``LEG``), so numbers are in leg lengths.

Encodings (channel counts in the constants below):

- content ``(F, CONTENT_CHANNELS)``: the 21 body joints' rotations as 6D (Hips relative
  to the facing frame, so a turned clip encodes identically; the others local), then the
  root channels: Hips height, root velocity on the floor in the facing frame (sideways,
  forward; per second) and turning velocity (rad/s). 6D rather than the paper's
  quaternions: a quaternion and its negation are one rotation, so sign-continuous
  quaternions still depend on where a window starts, and canonical ``w >= 0`` ones jump
  near 180 degrees; 6D is unique and continuous (Zhou et al. 2019), decoded by
  Gram-Schmidt.
- output ``(F, OUTPUT_CHANNELS)``: the rotations and the hips height of the content
  encoding (the network writes the pose and how high it carries the hips; where the body
  travels is the content's).
- 3D style ``(F, STYLE3D_CHANNELS)``: the body joints' positions relative to the root on
  the floor, in the facing frame (``kinematics.root_local``).
- 2D style ``(F, STYLE2D_CHANNELS)``: the joints a pose detector observes
  (``STYLE2D_JOINTS``), normalised by ``motion.keypoints.normalize`` itself (clip-mean
  Hips, median Neck-Hips length, y up), then taken relative to the Hips per frame. The
  per-frame centring drops the global travel, which the 3D style input does not see
  either and which depends on the camera (treadmill, panning) and on the clip length.
  Training motion reaches it through a weak-perspective projection (``project_2d``).

Networks read standardised channels: ``standardize(x, stats, kind)`` with statistics
from the training split (``FeatureStats``, saved as ``.npz``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion import canonical as C
from motion import keypoints
from motion import kinematics as K
from motion import rotations as rot
from motion.errors import MotionError
from motion.skeleton import Motion

FPS = C.FPS
LEG = C.leg_length()
ROOT = C.INDEX["joint_Root"]
HIPS = C.INDEX["Hips"]
# joint_Root never moves on canonical clips (the Hips carry the translation): left out.
BODY = np.arange(1, len(C.JOINTS))
FACING_JOINTS = tuple(C.INDEX[n] for n in ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R"))
# Gaussian sigma in frames: turning velocity and root-local positions without per-frame jitter.
FACING_SMOOTH = 2.0

ROTATION_CHANNELS = 6 * len(BODY)
ROOT_CHANNELS = 4  # hips height, velocity sideways, velocity forward, turning velocity
CONTENT_CHANNELS = ROTATION_CHANNELS + ROOT_CHANNELS
OUTPUT_CHANNELS = ROTATION_CHANNELS + 1  # and the hips height
STYLE3D_CHANNELS = 3 * len(BODY)

# Observed by OpenPose BODY_25 (see motion.keypoints); Hips is the per-frame origin.
STYLE2D_JOINTS = tuple(
    C.INDEX[n]
    for n in (
        "Neck", "Head",
        "UpperArm_L", "LowerArm_L", "Hand_L", "UpperArm_R", "LowerArm_R", "Hand_R",
        "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
        "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R",
    )
)  # fmt: skip
STYLE2D_CHANNELS = 2 * len(STYLE2D_JOINTS)
_OBSERVED_2D = np.zeros(len(C.JOINTS), dtype=bool)
_OBSERVED_2D[[HIPS, *STYLE2D_JOINTS]] = True

KINDS = ("content", "style3d", "style2d", "control")


def facing(gpos: np.ndarray) -> np.ndarray:
    """Per-frame facing rotations about +Y ``(F, 4)`` from global positions ``(F, 22, 3)``
    (hips and shoulders, smoothed over ``FACING_SMOOTH`` frames)."""
    dirs = K.facing_directions(gpos, *FACING_JOINTS, smooth=FACING_SMOOTH)
    return K.facing_rotations(dirs)


@dataclass(frozen=True)
class Encoded:
    """What one encoding pass yields: the content features and the frames decoding needs.

    ``content (F, CONTENT_CHANNELS)``, ``style3d (F, STYLE3D_CHANNELS)`` float32;
    ``facing (F, 4)``; ``gpos (F, 22, 3)`` global positions.
    """

    content: np.ndarray
    style3d: np.ndarray
    facing: np.ndarray
    gpos: np.ndarray


def encode(motion: Motion) -> Encoded:
    """Content and 3D style features of a canonical motion at 30 fps (one FK pass)."""
    C.check_motion(motion, "translator features")
    grot, gpos = K.fk(motion.lrot, motion.lpos, motion.skeleton.parents)
    face = facing(gpos)
    lrot = motion.lrot[:, BODY].copy()
    lrot[:, 0] = rot.mul(rot.inv(face), grot[:, HIPS])  # BODY[0] is Hips
    hips = gpos[:, HIPS]
    vel, turn = K.root_velocities(hips, face, motion.fps)
    root = np.concatenate([hips[:, 1:2] / LEG, vel / LEG, turn[:, None]], axis=-1)
    content = np.concatenate([rot.to_6d(lrot).reshape(len(lrot), -1), root], axis=-1)
    local = K.root_local(gpos[:, BODY], hips, face) / LEG
    return Encoded(
        content=content.astype(np.float32),
        style3d=local.reshape(len(local), -1).astype(np.float32),
        facing=face,
        gpos=gpos,
    )


def content_features(motion: Motion) -> np.ndarray:
    """Content input ``(F, CONTENT_CHANNELS)`` float32 (see the module docstring)."""
    return encode(motion).content


def style3d_features(motion: Motion) -> np.ndarray:
    """3D style input ``(F, STYLE3D_CHANNELS)`` float32: root-local body positions / LEG."""
    return encode(motion).style3d


# --------------------------------------------------------------------------- 2D style


def project_2d(gpos: np.ndarray, yaw: float = 0.0, scale: float = 1.0) -> np.ndarray:
    """Weak-perspective projection ``(F, 22, 2)`` (x right, y up) of ``gpos (F, 22, 3)``.

    The camera looks at the clip's mean facing direction (paper: the clip's local Z is the
    temporal mean of the per-frame forward directions), turned by ``yaw`` radians about
    +Y, no pitch or roll; ``scale`` multiplies the image. Seen from the front, the
    character's left (+X) is on the image's right, as in a video.
    """
    gpos = np.asarray(gpos, dtype=np.float64)
    dirs = K.facing_directions(gpos, *FACING_JOINTS).mean(axis=0)
    heading = np.arctan2(dirs[0], dirs[2]) if np.hypot(dirs[0], dirs[2]) > 1e-6 else 0.0
    view = rot.mul(rot.about_y(np.asarray(yaw)), rot.inv(rot.about_y(np.asarray(heading))))
    cam = rot.apply(view, gpos)
    return scale * cam[..., :2]


def _style2d_from_normalized(positions: np.ndarray) -> np.ndarray:
    rel = positions[:, STYLE2D_JOINTS] - positions[:, HIPS : HIPS + 1]
    return rel.reshape(len(rel), -1).astype(np.float32)


def _resample_positions(positions: np.ndarray, fps: float) -> np.ndarray:
    """Linear resampling of ``(F, J, 2)`` from ``fps`` to ``FPS`` (the first frame kept)."""
    if abs(fps - FPS) <= 1e-4 * FPS or len(positions) < 2:
        return positions
    t_src = np.arange(len(positions)) / fps
    t_dst = np.arange(int(np.floor(t_src[-1] * FPS + 1e-3)) + 1) / FPS
    flat = positions.reshape(len(positions), -1)
    out = np.stack([np.interp(t_dst, t_src, flat[:, c]) for c in range(flat.shape[1])], axis=-1)
    return out.reshape((len(t_dst),) + positions.shape[1:])


def style2d_from_keypoints(kp: keypoints.Keypoints2D) -> np.ndarray:
    """2D style input ``(F', STYLE2D_CHANNELS)`` float32 of a video's keypoints, at 30 fps.

    Normalised by ``keypoints.normalize`` (raises ``MotionError`` when the torso has no
    length), then resampled linearly from ``kp.fps`` to 30 fps.
    """
    normalized = keypoints.normalize(kp)
    return _style2d_from_normalized(_resample_positions(normalized, kp.fps))


def keypoints_of_positions(
    gpos: np.ndarray, yaw: float = 0.0, scale: float = 1.0
) -> keypoints.Keypoints2D:
    """3D motion ``gpos (F, 22, 3)`` at 30 fps as a video's keypoints: seen through
    ``project_2d(gpos, yaw, scale)``, with the joints OpenPose BODY_25 observes."""
    projected = project_2d(gpos, yaw, scale)
    confidence = np.broadcast_to(_OBSERVED_2D.astype(np.float64), projected.shape[:2])
    return keypoints.Keypoints2D(projected, confidence, _OBSERVED_2D, FPS, "projection")


def style2d_from_positions(gpos: np.ndarray, yaw: float = 0.0, scale: float = 1.0) -> np.ndarray:
    """2D style input ``(F, STYLE2D_CHANNELS)`` of 3D motion ``gpos (F, 22, 3)`` at 30 fps,
    normalised exactly as real keypoints are (:func:`keypoints_of_positions`)."""
    return style2d_from_keypoints(keypoints_of_positions(gpos, yaw, scale))


# --------------------------------------------------------------------------- decoding


def rotations_from_output(output: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Canonical local rotations ``(F, 22, 4)`` from a network output ``(F, OUTPUT_CHANNELS)``
    (unstandardised 6D) and the facing rotations ``(F, 4)`` the Hips are relative to.

    Gram-Schmidt makes any 6 numbers a rotation; joint_Root gets the identity, so the
    Hips rotation is global (canonical clips keep joint_Root still).
    """
    output = np.asarray(output, dtype=np.float64)
    num = len(output)
    six = output[:, :ROTATION_CHANNELS].reshape(num, len(BODY), 6)
    body = rot.from_6d(six)
    lrot = rot.identity((num, len(C.JOINTS)))
    lrot[:, BODY] = body
    lrot[:, HIPS] = rot.mul(face, body[:, 0])
    return lrot


def decode_motion(output: np.ndarray, content: Motion, face: np.ndarray | None = None) -> Motion:
    """A canonical motion with the network's rotations and hips height on the content's
    root trajectory.

    ``output (F, OUTPUT_CHANNELS)`` unstandardised, frame-aligned with ``content`` (without
    its last channel, the hips height, the content's is kept); ``face`` the content's
    facing rotations (recomputed when None). The content's joint_Root rotation and the
    hips' travel over the floor are kept.
    """
    C.check_motion(content, "translator features")
    if len(output) != content.num_frames:
        raise MotionError(f"output has {len(output)} frames, content {content.num_frames}")
    if face is None:
        face = facing(K.global_positions(content))
    lrot = rotations_from_output(output, face)
    root = content.lrot[:, ROOT]
    lrot[:, ROOT] = root
    lrot[:, HIPS] = rot.mul(rot.inv(root), lrot[:, HIPS])
    lpos = content.lpos.copy()
    if output.shape[1] > ROTATION_CHANNELS:  # the hips height, in the root's frame
        hips = content.lpos[:, ROOT] + rot.apply(root, content.lpos[:, HIPS])
        lift = np.zeros_like(hips)
        lift[:, 1] = output[:, ROTATION_CHANNELS] * LEG - hips[:, 1]
        lpos[:, HIPS] += rot.apply(rot.inv(root), lift)
    return content.replace(lrot=lrot, lpos=lpos)


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class FeatureStats:
    """Per-channel ``mean`` and ``std`` ``(C,)`` float32 of each kind in ``KINDS``.

    The output channels use the content's rotation channels (``kind="output"``).
    """

    mean: dict[str, np.ndarray]
    std: dict[str, np.ndarray]

    @staticmethod
    def from_arrays(arrays) -> FeatureStats:
        """From a mapping of ``<kind>_mean`` and ``<kind>_std`` arrays (as :func:`save_stats`
        writes them)."""
        kinds = [k.removesuffix("_mean") for k in arrays if k.endswith("_mean")]
        return FeatureStats(
            {k: arrays[f"{k}_mean"] for k in kinds}, {k: arrays[f"{k}_std"] for k in kinds}
        )

    def get(self, kind: str) -> tuple[np.ndarray, np.ndarray]:
        if kind == "output":
            return self.mean["content"][:OUTPUT_CHANNELS], self.std["content"][:OUTPUT_CHANNELS]
        return self.mean[kind], self.std[kind]


# Floor for the std: near-constant channels (toe twist) would otherwise be blown up.
STD_FLOOR = 1e-2


def compute_stats(arrays: dict[str, list[np.ndarray]]) -> FeatureStats:
    """Statistics from lists of ``(F, C)`` arrays per kind (pooled over all frames)."""
    mean, std = {}, {}
    for kind, items in arrays.items():
        x = np.concatenate([np.asarray(a, dtype=np.float64) for a in items], axis=0)
        mean[kind] = x.mean(axis=0).astype(np.float32)
        std[kind] = np.maximum(x.std(axis=0), STD_FLOOR).astype(np.float32)
    return FeatureStats(mean, std)


def standardize(x: np.ndarray, stats: FeatureStats, kind: str) -> np.ndarray:
    """``(x - mean) / std`` for ``x (..., C)`` of ``kind``, float32."""
    mean, std = stats.get(kind)
    return ((np.asarray(x, dtype=np.float32) - mean) / std).astype(np.float32)


def unstandardize(x: np.ndarray, stats: FeatureStats, kind: str) -> np.ndarray:
    """Inverse of :func:`standardize`."""
    mean, std = stats.get(kind)
    return (np.asarray(x, dtype=np.float32) * std + mean).astype(np.float32)


def save_stats(path: str | Path, stats: FeatureStats) -> None:
    arrays = {f"{kind}_mean": stats.mean[kind] for kind in stats.mean}
    arrays |= {f"{kind}_std": stats.std[kind] for kind in stats.std}
    np.savez(path, **arrays)


def load_stats(path: str | Path) -> FeatureStats:
    with np.load(path) as z:
        return FeatureStats.from_arrays({k: z[k] for k in z.files})


# --------------------------------------------------------------------------- restyler input

# What the translator's restyler reads of the content: the paths of the head, hands, feet
# and toes about the hips, and how the body travels. The rest of the pose (spine, elbows,
# knees, how the joints are held) it writes from the style code.
CONTROL_JOINTS = tuple(
    int(np.flatnonzero(BODY == C.INDEX[n])[0])
    for n in ("Head", "Hand_L", "Hand_R", "Foot_L", "Foot_R", "Toes_L", "Toes_R")
)  # indices among BODY, i.e. among the 21 joints of the style3d encoding
CONTROL_CHANNELS = 3 * len(CONTROL_JOINTS) + ROOT_CHANNELS


def control_features(content: np.ndarray, style3d: np.ndarray) -> np.ndarray:
    """``(F, CONTROL_CHANNELS)`` float32 of one whole clip's content and 3D style encodings:
    the control joints relative to the hips (facing frame, leg lengths), then the root
    channels (hips height, velocity sideways and forward, turning). Positions and hips
    height are taken relative to their mean over the clip: the posture is the style's to
    choose, the movement about it is the content's."""
    pos = np.asarray(style3d, dtype=np.float32).reshape(len(style3d), -1, 3)
    rel = (pos[:, CONTROL_JOINTS] - pos[:, :1]).reshape(len(pos), -1)
    root = np.array(content[:, ROTATION_CHANNELS:], dtype=np.float32)
    x = np.concatenate([rel - rel.mean(axis=0), root], axis=1)
    x[:, -ROOT_CHANNELS] -= x[:, -ROOT_CHANNELS].mean()
    return x.astype(np.float32)


def restyler_input(content: np.ndarray, style3d: np.ndarray, stats: FeatureStats) -> np.ndarray:
    """The restyler's input ``(F, CONTROL_CHANNELS)``: :func:`control_features`
    standardised (kind ``control``)."""
    return standardize(control_features(content, style3d), stats, "control")


# --------------------------------------------------------------------------- time


def pad_frames(x: np.ndarray, multiple: int) -> np.ndarray:
    """``x (F, ...)`` with its last frame repeated up to a multiple of ``multiple`` frames
    (networks need their stride; crop the output back to ``F``)."""
    x = np.asarray(x)
    extra = (-len(x)) % multiple
    if extra == 0:
        return x
    return np.concatenate([x, np.repeat(x[-1:], extra, axis=0)], axis=0)


def velocity_factor(motion: Motion) -> float:
    """The paper's velocity factor (eq. 2): the temporal mean of the largest joint speed in
    the root-local frame, in skeleton units per second."""
    C.check_motion(motion, "translator features")
    return encoded_velocity_factor(encode(motion), motion.fps)


def encoded_velocity_factor(enc: Encoded, fps: float = FPS) -> float:
    """:func:`velocity_factor` from an encoding already made (no second FK pass)."""
    local = enc.style3d.reshape(len(enc.style3d), len(BODY), 3).astype(np.float64) * LEG
    speed = np.linalg.norm(K.velocities(local, fps), axis=-1)
    return float(speed.max(axis=-1).mean())


def time_warp(motion: Motion, factor: float, num_frames: int | None = None) -> Motion:
    """The motion played ``factor`` times faster (``> 1`` shortens it), same fps.

    Resamples (slerp, linear translations) at evenly spaced times from the first to the
    last frame, ``round((F - 1) / factor) + 1`` frames unless ``num_frames`` is given, so
    warping by ``f`` and back by ``1 / f`` with the original ``num_frames`` returns the
    original frames within interpolation error. The service warps the output by
    ``velocity_factor(style) / velocity_factor(content)``.
    """
    if not np.isfinite(factor) or factor <= 0:
        raise MotionError(f"time warp factor must be positive, got {factor}")
    if num_frames is None:
        num_frames = int(round((motion.num_frames - 1) / factor)) + 1
    num_frames = max(int(num_frames), 1)
    if motion.num_frames < 2 or num_frames < 2:
        return K.resample_at(motion, np.zeros(num_frames), motion.fps)
    times = np.linspace(0.0, motion.num_frames - 1, num_frames)
    return K.resample_at(motion, times, motion.fps)

"""glTF 2.0 in and out: ``loads`` a ``.glb`` (or a ``.gltf`` with embedded buffers) to a
:class:`~motion.skeleton.Motion`, ``dumps`` a new motion back into the file it came from.

The skin's joints are the rig: their common ancestor (or the highest node above it that
the animation moves) is the root, every node on the way down to a joint is a joint. One
animation (the first that moves the rig) is the motion, every channel sampled at a fixed
frame rate read off the keyframe times. Each joint is re-expressed in a frame that the
file's rest pose (the nodes' own TRS) leaves aligned with the world, as a BVH exporter
does, so identity rotations are the rest pose and the retargeting reads the file as it
would a BVH of it. Transforms of the nodes above the root and uniform scales are folded
into the root and the offsets (glTF is Y up, metres), and unfolded on the way out.
glTF has no End Sites: a leaf joint ends at its node.

Writing keeps every node, mesh, skin, material and other animation of the file: the
animation that was read gets new samplers and channels (rotation of every rig joint,
translation where it moves), in the accessors and buffer views the old ones used alone,
so a file restyled twice does not grow (:mod:`motion.gltf_writer`). Scale and
morph-weight channels of that animation are not carried. pygltflib reads and writes the
container (:mod:`motion.gltf_container` unpacks its accessors). Every problem raises
:class:`~motion.errors.MotionError` naming it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from motion import rotations as rot
from motion.bvh import MAX_ABS_VALUE
from motion.errors import MotionError
from motion.gltf_container import GltfDocument, malformed_as_motion_error
from motion.gltf_writer import AnimationWriter
from motion.skeleton import Motion, Skeleton

DEFAULT_FPS = 30.0
MAX_FRAMES = 200_000  # a bound before allocation; callers pass their own, smaller limit
_COMMON_FPS = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 90.0, 100.0, 120.0, 240.0)


_ROTATION_ORDER = ("Zrotation", "Yrotation", "Xrotation")
_POSITION = ("Xposition", "Yposition", "Zposition")


_PATHS = ("translation", "rotation")


def is_gltf(data: bytes) -> bool:
    """Whether ``data`` looks like glTF: the GLB magic, or JSON with an ``asset`` member."""
    if data[:4] == b"glTF":
        return True
    head = data[:4096].lstrip(b"\xef\xbb\xbf \t\r\n")
    return head[:1] == b"{" and b'"asset"' in data[:1_000_000]


def load(path: str | os.PathLike, **options) -> Motion:
    """Read a ``.glb`` or ``.gltf`` file (buffers embedded); ``options`` as for :func:`loads`."""
    with open(path, "rb") as f:
        return loads(f.read(), **options)


def loads(
    data: bytes, *, max_frames: int | None = None, rest_if_unanimated: bool = False
) -> Motion:
    """The motion of the skin in glTF ``data`` (GLB bytes, or glTF JSON with embedded buffers).

    More than ``max_frames`` frames (default :data:`MAX_FRAMES`) raise a ``"too-large"``
    error before anything is sampled. With ``rest_if_unanimated`` a file with no animation
    reads as one frame of its rest pose (a rig to retarget onto) instead of an error.
    """
    return read(data, max_frames=max_frames, rest_if_unanimated=rest_if_unanimated).motion


class GltfFile:
    """A parsed glTF file: ``motion`` (its rig's motion, as :func:`loads` reads it) and
    :meth:`write`, which puts a new motion into it (as :func:`dumps`) without parsing the
    file again (pygltflib's parsing is the slow part)."""

    def __init__(self, doc: GltfDocument, motion: Motion) -> None:
        self._doc = doc
        self.motion = motion

    def write(self, motion: Motion) -> bytes:
        """GLB bytes of this file with ``motion`` in place of its animation."""
        import copy

        with malformed_as_motion_error():
            doc = copy.copy(self._doc)
            doc.gltf = copy.deepcopy(self._doc.gltf)  # the writer edits the document
            doc.gltf.set_binary_blob(self._doc.gltf.binary_blob())
            return _write(doc, motion)


def read(
    data: bytes, *, max_frames: int | None = None, rest_if_unanimated: bool = False
) -> GltfFile:
    """Parse glTF ``data`` once: its motion (options as for :func:`loads`) and a writer."""
    with malformed_as_motion_error():
        doc = GltfDocument(data)
        return GltfFile(doc, _read(doc, max_frames or MAX_FRAMES, rest_if_unanimated))


def _read(doc: GltfDocument, max_frames: int, rest_if_unanimated: bool) -> Motion:
    rig = _find_rig(doc)
    if rig.animation is None:
        if not rest_if_unanimated:
            raise MotionError(
                "the glTF file has no animation that moves the skin's joints", kind="unusable"
            )
        lrot = rig.rest_rot[None].copy()
        lpos = rig.rest_pos[None].copy()
        fps, start = DEFAULT_FPS, 0.0
    else:
        tracks = _read_tracks(doc, rig)
        fps, start, frames = _frame_grid(tracks, max_frames)
        times = start + np.arange(frames) / fps
        lrot = np.repeat(rig.rest_rot[None], frames, axis=0)
        lpos = np.repeat(rig.rest_pos[None], frames, axis=0)
        for track in tracks:
            values = _sample(track, times)
            if track.path == "rotation":
                lrot[:, track.joint] = values
            else:
                lpos[:, track.joint] = values
    lrot, lpos = _to_world_aligned(rig, lrot, lpos)
    offsets = _world_offsets(rig)
    largest = max(np.abs(offsets).max(initial=0.0), np.abs(lpos).max(initial=0.0))
    if largest > MAX_ABS_VALUE:  # as the BVH reader: so any clip read can be written as BVH
        raise MotionError(f"a joint position of {largest:g} is absurdly large")
    # position channels where a joint leaves its rest offset (BVH output keeps them)
    moving = np.abs(lpos - offsets).max(axis=0).max(axis=-1) > 1e-6 * max(rig.height, 1e-6)
    channels = tuple(
        _POSITION + _ROTATION_ORDER if j == 0 or moving[j] else _ROTATION_ORDER
        for j in range(len(rig.nodes))
    )
    skeleton = Skeleton(rig.names, rig.parents, offsets, channels)
    return Motion(skeleton, fps, lrot, lpos)


def dumps(original: bytes, motion: Motion) -> bytes:
    """GLB bytes of the glTF file ``original`` with ``motion`` in place of its animation.

    ``motion`` must be on the file's rig (the joints :func:`loads` reads, same names and
    order); its frames are written at ``motion.fps`` from the old animation's start time.
    Everything else in the file is kept. A file with no animation gets a new one.
    """
    with malformed_as_motion_error():
        return _write(GltfDocument(original), motion)


def _write(doc: GltfDocument, motion: Motion) -> bytes:
    rig = _find_rig(doc)
    names = tuple(motion.skeleton.names)
    if names != rig.names:
        missing = [n for n in rig.names if n not in names]
        raise MotionError(
            "the motion is not on the glTF file's rig"
            + (f": it lacks {', '.join(missing[:5])}" if missing else ": joints differ"),
            kind="unusable",
        )
    start = 0.0
    old_channels: set[tuple[int, str]] = set()
    if rig.animation is not None:
        tracks = _read_tracks(doc, rig)
        start = min(float(t.times[0]) for t in tracks)
        old_channels = {(t.joint, t.path) for t in tracks}
    lrot, lpos = _from_world_aligned(rig, motion.lrot, motion.lpos)
    times = (start + np.arange(motion.num_frames) / motion.fps).astype(np.float32)
    rest = rig.rest_pos[None]
    lrot = rot.make_continuous(lrot)  # neighbouring keys on one side: linear blends agree
    outputs: list[tuple[int, str, np.ndarray]] = []
    for j, node in enumerate(rig.nodes):
        outputs.append((node, "rotation", lrot[:, j]))
        moves = np.abs(lpos[:, j] - rest[:, j]).max() > 1e-6 * max(rig.height, 1e-6)
        if j == 0 or moves or (j, "translation") in old_channels:
            outputs.append((node, "translation", lpos[:, j]))
    return AnimationWriter(doc, rig.animation).write(times, outputs)


@dataclass
class _Rig:
    nodes: list[int]  # glTF node index of each joint, parents first
    names: tuple[str, ...]
    parents: np.ndarray  # (J,)
    rest_rot: np.ndarray  # (J, 4) the nodes' own rotations
    rest_pos: np.ndarray  # (J, 3) the nodes' own translations
    scale: np.ndarray  # (J,) uniform scale each joint applies to its children's translations
    above_rot: np.ndarray  # (4,) world transform of the nodes above the root
    above_pos: np.ndarray  # (3,)
    above_scale: float
    world_rest: np.ndarray  # (J, 4) rest world rotation of each joint
    animation: int | None
    height: float


def _node_trs(node, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(translation (3,), rotation (4,), scale (3,))`` of a node, from TRS or its matrix."""
    try:
        if node.matrix is not None and len(node.matrix) == 16:
            m = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T  # column-major
            scale = np.linalg.norm(m[:3, :3], axis=0)
            if not np.isfinite(m).all() or (scale < 1e-12).any() or np.linalg.det(m[:3, :3]) < 0:
                raise MotionError(f"node {index} has a degenerate or mirroring matrix")
            return m[:3, 3].copy(), rot.from_matrix(m[:3, :3] / scale), scale
        t = np.asarray(node.translation if node.translation is not None else [0, 0, 0], float)
        r = np.asarray(node.rotation if node.rotation is not None else [0, 0, 0, 1], float)
        s = np.asarray(node.scale if node.scale is not None else [1, 1, 1], float)
    except (TypeError, ValueError):
        raise MotionError(f"node {index} has a transform that is not numbers") from None
    if t.shape != (3,) or r.shape != (4,) or s.shape != (3,):
        raise MotionError(f"node {index} has a transform of the wrong size")
    if not (np.isfinite(t).all() and np.isfinite(r).all() and np.isfinite(s).all()):
        raise MotionError(f"node {index} has a transform that is not finite")
    if np.linalg.norm(r) < 1e-6:
        raise MotionError(f"node {index} has a zero rotation quaternion")
    return t, rot.normalize(r), s


def _uniform(scale: np.ndarray, what: str) -> float:
    s = float(np.mean(scale))
    if s <= 0 or np.abs(scale - s).max() > 1e-3 * s:
        raise MotionError(
            f"{what} is scaled unevenly or mirrored ({', '.join(f'{v:g}' for v in scale)}): "
            "only uniform scales can be carried",
            kind="unusable",
        )
    return s


def _find_rig(doc: GltfDocument) -> _Rig:
    gltf = doc.gltf
    nodes = gltf.nodes or []
    skins = gltf.skins or []
    if not skins:
        raise MotionError(
            "the glTF file has no skin: it needs a skinned, rigged character", kind="unusable"
        )
    parent: dict[int, int] = {}
    for i, node in enumerate(nodes):
        for c in node.children or []:
            doc.item("nodes", c, f"node {i}'s children")
            if c in parent or c == i:
                raise MotionError(f"node {c} has more than one parent")
            parent[c] = i

    def ancestors(i: int) -> list[int]:
        chain = [i]
        while chain[-1] in parent:
            chain.append(parent[chain[-1]])
            if len(chain) > len(nodes):
                raise MotionError("the node hierarchy has a cycle")
        return chain

    skin = max(skins, key=lambda s: len(s.joints or []))
    joints = list(dict.fromkeys(skin.joints or []))
    if not joints:
        raise MotionError("the glTF file's skin has no joints", kind="unusable")
    for j in joints:
        doc.item("nodes", j, "the skin's joints")
    chains = [ancestors(j) for j in joints]
    common = set(chains[0]).intersection(*map(set, chains[1:]))
    if not common:
        raise MotionError("the skin's joints have no common ancestor node", kind="unusable")
    root = next(n for n in chains[0] if n in common)  # the lowest common ancestor

    animation = _pick_animation(doc, set().union(*map(set, chains)))
    if animation is not None:  # raise the root to the highest node above it that moves
        moved = {
            ch.target.node
            for ch in gltf.animations[animation].channels or []
            if ch.target is not None and ch.target.path in _PATHS
        }
        for n in ancestors(root)[1:]:
            if n in moved:
                root = n
    in_rig = {root}
    for chain in chains:
        for n in chain:
            if n == root:
                break
            in_rig.add(n)
    if animation is not None and not _animates(doc, animation, in_rig):
        animation = None

    order: list[int] = []
    stack = [root]
    while stack:  # depth first, children in file order: parents come first
        n = stack.pop()
        order.append(n)
        stack.extend(c for c in reversed(nodes[n].children or []) if c in in_rig)
    index = {n: k for k, n in enumerate(order)}
    parents = np.array([-1] + [index[parent[n]] for n in order[1:]])
    trs = [_node_trs(nodes[n], n) for n in order]
    rest_pos = np.array([t for t, _, _ in trs])
    rest_rot = np.array([r for _, r, _ in trs])
    has_children = {parents[k] for k in range(1, len(order))}
    scale = np.array(
        [
            _uniform(s, f"joint node {order[k]}") if k in has_children else 1.0
            for k, (_, _, s) in enumerate(trs)
        ]
    )

    above_rot, above_pos, above_scale = rot.identity(), np.zeros(3), 1.0
    for n in reversed(ancestors(root)[1:]):  # world transform of the nodes above the root
        t, r, s = _node_trs(nodes[n], n)
        s = _uniform(s, f"node {n} above the rig")
        above_pos = above_pos + above_scale * rot.apply(above_rot, t)
        above_rot = rot.mul(above_rot, r)
        above_scale *= s

    world_rest = np.empty((len(order), 4))
    for k in range(len(order)):
        p = parents[k]
        world_rest[k] = rot.mul(above_rot if p < 0 else world_rest[p], rest_rot[k])
    names = _unique_names([nodes[n].name or f"node{n}" for n in order], order)
    rig = _Rig(
        order, names, parents, rest_rot, rest_pos, scale, above_rot, above_pos, above_scale,
        world_rest, animation, 1.0,
    )  # fmt: skip
    offsets = _world_offsets(rig)
    gpos = np.zeros_like(offsets)
    for k in range(1, len(order)):
        gpos[k] = gpos[parents[k]] + offsets[k]
    rig.height = float(max((gpos.max(axis=0) - gpos.min(axis=0)).max(), 1e-6))
    return rig


def _unique_names(names: list[str], order: list[int]) -> tuple[str, ...]:
    seen: dict[str, int] = {}
    for n in names:
        seen[n] = seen.get(n, 0) + 1
    return tuple(n if seen[n] == 1 else f"{n}.{node}" for n, node in zip(names, order, strict=True))


def _pick_animation(doc: GltfDocument, nodes: set[int]) -> int | None:
    for i in range(len(doc.gltf.animations or [])):
        if _animates(doc, i, nodes):
            return i
    return None


def _animates(doc: GltfDocument, animation: int, nodes: set[int]) -> bool:
    return any(
        ch.target is not None and ch.target.node in nodes and ch.target.path in _PATHS
        for ch in doc.gltf.animations[animation].channels or []
    )


def _parent_frames(rig: _Rig) -> tuple[np.ndarray, np.ndarray]:
    """Rest world rotation ``(J, 4)`` and cumulative scale ``(J,)`` of each joint's parent."""
    p = rig.parents
    prot = np.where((p < 0)[:, None], rig.above_rot[None], rig.world_rest[np.maximum(p, 0)])
    cum = np.empty(len(p))
    for k in range(len(p)):
        cum[k] = (rig.above_scale if p[k] < 0 else cum[p[k]]) * rig.scale[k]
    pscale = np.where(p < 0, rig.above_scale, cum[np.maximum(p, 0)])
    return prot, pscale


def _world_offsets(rig: _Rig) -> np.ndarray:
    prot, pscale = _parent_frames(rig)
    out = pscale[:, None] * rot.apply(prot, rig.rest_pos)
    out[0] += rig.above_pos
    return out


def _to_world_aligned(rig: _Rig, lrot: np.ndarray, lpos: np.ndarray):
    """The nodes' local TRS -> joint frames that the rest pose leaves world-aligned."""
    prot, pscale = _parent_frames(rig)
    out_rot = rot.mul(rot.mul(prot, lrot), rot.inv(rig.world_rest))
    out_pos = pscale[:, None] * rot.apply(prot, lpos)
    out_pos[:, 0] += rig.above_pos
    return rot.normalize(out_rot), out_pos


def _from_world_aligned(rig: _Rig, lrot: np.ndarray, lpos: np.ndarray):
    prot, pscale = _parent_frames(rig)
    out_rot = rot.mul(rot.mul(rot.inv(prot), lrot), rig.world_rest)
    pos = np.array(lpos, dtype=np.float64)
    pos[:, 0] -= rig.above_pos
    out_pos = rot.apply(rot.inv(prot), pos) / pscale[:, None]
    return rot.normalize(out_rot), out_pos


@dataclass
class _Track:
    joint: int
    path: str
    interpolation: str
    times: np.ndarray  # (K,)
    values: np.ndarray  # (K, D), or (K, 3, D) for CUBICSPLINE: in-tangent, value, out-tangent


def _read_tracks(doc: GltfDocument, rig: _Rig) -> list[_Track]:
    animation = doc.gltf.animations[rig.animation]
    samplers = animation.samplers or []
    joint_of = {n: k for k, n in enumerate(rig.nodes)}
    tracks: list[_Track] = []
    for ch in animation.channels or []:
        if ch.target is None or ch.target.node not in joint_of or ch.target.path not in _PATHS:
            continue
        joint = joint_of[ch.target.node]
        what = f"the {ch.target.path} of joint {rig.names[joint]!r}"
        if not isinstance(ch.sampler, int) or not 0 <= ch.sampler < len(samplers):
            raise MotionError(f"{what} refers to sampler {ch.sampler!r}, which does not exist")
        sampler = samplers[ch.sampler]
        interpolation = sampler.interpolation or "LINEAR"
        if interpolation not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise MotionError(
                f"{what} uses interpolation {interpolation!r}: LINEAR, STEP and CUBICSPLINE "
                "are supported"
            )
        times = doc.accessor(sampler.input, f"keyframe times of {what}")[:, 0]
        values = doc.accessor(sampler.output, f"keyframes of {what}")
        width = 4 if ch.target.path == "rotation" else 3
        per_key = 3 if interpolation == "CUBICSPLINE" else 1
        if values.shape != (len(times) * per_key, width):
            raise MotionError(
                f"{what} has {len(values)} keyframe values of width {values.shape[1]} for "
                f"{len(times)} times ({interpolation} needs {per_key} of width {width} each)"
            )
        if np.any(np.diff(times) < 0) or times[0] < 0:
            raise MotionError(f"keyframe times of {what} go backwards or start before 0")
        if per_key == 3:
            values = values.reshape(len(times), 3, width)
        if width == 4:
            key = values if per_key == 1 else values[:, 1]
            if (np.linalg.norm(key, axis=-1) < 1e-6).any():
                raise MotionError(f"{what} has a zero rotation quaternion")
        tracks.append(_Track(joint, ch.target.path, interpolation, times, values))
    return tracks


def _frame_grid(tracks: list[_Track], max_frames: int) -> tuple[float, float, int]:
    """``(fps, start time, frames)``: the keyframes' common spacing, else a usual rate
    that puts every key on a frame, else :data:`DEFAULT_FPS`."""
    times = np.unique(np.round(np.concatenate([t.times for t in tracks]), 6))
    start, end = float(times[0]), float(times[-1])
    fps = DEFAULT_FPS
    if len(times) > 1:
        spacing = float(np.diff(times).min())
        first = 1.0 / spacing
        if abs(first - round(first)) < 1e-3 * first:
            first = float(round(first))
        for candidate in (first, *_COMMON_FPS):
            if candidate > 1000:
                continue
            steps = (times - start) * candidate
            if np.abs(steps - np.round(steps)).max() < 0.02:
                fps = candidate
                break
    frames = int(round((end - start) * fps)) + 1
    if frames > max_frames:
        raise MotionError(
            f"the animation lasts {end - start:.1f} s, {frames} frames at {fps:g} fps: over the "
            f"limit of {max_frames}",
            kind="too-large",
            limit=max_frames,
        )
    return fps, start, frames


def _sample(track: _Track, times: np.ndarray) -> np.ndarray:
    """Values ``(F, D)`` of a track at ``times``, held before its first and after its last key."""
    keys, values = track.times, track.values
    if track.interpolation == "CUBICSPLINE":
        points = values[:, 1]
    else:
        points = values
    if len(keys) == 1:
        out = np.repeat(points[:1], len(times), axis=0)
    elif track.interpolation == "STEP":
        i = np.clip(np.searchsorted(keys, times + 1e-6, side="right") - 1, 0, len(keys) - 1)
        out = points[i]
    else:
        i = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 2)
        dt = keys[i + 1] - keys[i]
        u = np.clip((times - keys[i]) / np.where(dt > 0, dt, 1.0), 0.0, 1.0)
        if track.interpolation == "LINEAR":
            if track.path == "rotation":
                out = rot.slerp(points[i], points[i + 1], u)
            else:
                out = points[i] + u[:, None] * (points[i + 1] - points[i])
        else:  # cubic Hermite spline, tangents scaled by the key spacing (glTF appendix C)
            u = u[:, None]
            u2, u3 = u * u, u * u * u
            d = dt[:, None]
            out = (
                (2 * u3 - 3 * u2 + 1) * points[i]
                + (u3 - 2 * u2 + u) * d * values[i, 2]
                + (-2 * u3 + 3 * u2) * points[i + 1]
                + (u3 - u2) * d * values[i + 1, 0]
            )
    return rot.normalize(out) if track.path == "rotation" else out

"""A new animation written straight into an FBX file's bytes: the file that was sent, with
its armature's bone curves replaced and everything else (meshes, skin, materials, other
objects and their animation, the file's own axes, units and node properties) kept byte for
byte. It takes a few milliseconds where Blender's exporter takes hundreds.

:func:`plan` reads the file (:mod:`motion.fbx_binary`) and finds each bone's FBX node by
name, then checks on the file's first animated frame that every bone's FBX transform (its
curves through the node's pre- and post-rotation, pivots and offsets, as FBX composes them:
``T Roff Rp Rpre R Rpost^-1 Rp^-1 Soff Sp S Sp^-1``) is what Blender read of it: a child's
is its parent's armature-space matrix inverted times its own, a root bone's its own up to a
fixed matrix (the nodes above it, the axis and unit conversion) taken from that frame. A
file where that does not hold (a bone Blender made or corrected, scaled bones, an armature
node that moves, several takes, no animation) gets the reason instead, and the caller
exports through Blender. :meth:`Plan.write` keys every frame of a new pose (armature-space
bone matrices) as each bone's ``Lcl Translation`` and ``Lcl Rotation`` (Euler angles in the
node's rotation order, continuous), and sets the take's, the stack's and the scene's time
span and, where it changed, the frame rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from motion import fbx_binary as B
from motion.errors import MotionError

TICKS_PER_SECOND = 46_186_158_000
CHANNELS = (b"d|X", b"d|Y", b"d|Z")
_ORDERS = {0: "xyz", 1: "xzy", 2: "yzx", 3: "yxz", 4: "zxy", 5: "zyx", 6: "xyz"}
# FBX GlobalSettings TimeMode -> frames per second (14: CustomFrameRate)
_TIME_MODES = {
    1: 120.0,
    2: 100.0,
    3: 60.0,
    4: 50.0,
    5: 48.0,
    6: 30.0,
    7: 30.0,
    8: 29.97,
    9: 29.97,
    10: 25.0,
    11: 24.0,
    12: 1000.0,
    13: 23.976,
    15: 96.0,
    16: 72.0,
    17: 59.94,
}
_CUSTOM = 14
# what Blender's exporter writes for every curve (linear keys, its tangent flags)
_KEY_FLAGS = np.array([24836], dtype=np.int32)
_KEY_DATA = np.array(
    [0.0, 0.0, np.frombuffer(np.int32(218434821).tobytes(), np.float32)[0], 0.0], dtype=np.float32
)
TOLERANCE = 1e-3  # of the skeleton's size (translations) and of a rotation matrix's entries


def _props(node: B.Node | None) -> dict[bytes, list]:
    p70 = node.child(b"Properties70") if node is not None else None
    return {v[0]: v[4:] for v in (p.values() for p in p70.children)} if p70 else {}


def _translation(v: np.ndarray) -> np.ndarray:
    m = np.zeros(v.shape[:-1] + (4, 4))
    m[..., :3, :3] = np.eye(3)
    m[..., :3, 3] = v
    m[..., 3, 3] = 1.0
    return m


def _rotation(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """``(..., 3)`` X, Y, Z angles in degrees applied in ``order`` (FBX's, extrinsic) -> 4x4."""
    shape = angles_deg.shape[:-1]
    seq = angles_deg.reshape(-1, 3)[:, ["xyz".index(a) for a in order]]
    m = np.zeros(shape + (4, 4))
    m[..., :3, :3] = (
        Rotation.from_euler(order, seq, degrees=True).as_matrix().reshape(shape + (3, 3))
    )
    m[..., 3, 3] = 1.0
    return m


@dataclass
class _Node:
    """One bone's FBX node: its id, the static parts of its transform, its rotation order."""

    id: int
    props: dict[bytes, list]
    order: str
    before: np.ndarray  # Roff Rp Rpre
    after: np.ndarray  # Rpost^-1 Rp^-1 Soff Sp S Sp^-1

    @classmethod
    def of(cls, model: B.Node, template: dict[bytes, list]) -> _Node:
        props = {**template, **_props(model)}

        def vec(name: bytes, default: float) -> np.ndarray:
            return np.array(props.get(name, [default] * 3)[:3], dtype=np.float64)

        active = bool(props.get(b"RotationActive", [0])[0])
        order = _ORDERS.get(int(props.get(b"RotationOrder", [0])[0]), "xyz") if active else "xyz"
        pre = _rotation(vec(b"PreRotation", 0.0), "xyz") if active else np.eye(4)
        post = _rotation(vec(b"PostRotation", 0.0), "xyz") if active else np.eye(4)
        pivot = vec(b"RotationPivot", 0.0)
        scale_pivot = vec(b"ScalingPivot", 0.0)
        scale = np.diag([*vec(b"Lcl Scaling", 1.0), 1.0])
        before = _translation(vec(b"RotationOffset", 0.0)) @ _translation(pivot) @ pre
        after = (
            np.linalg.inv(post)
            @ _translation(-pivot)
            @ _translation(vec(b"ScalingOffset", 0.0))
            @ _translation(scale_pivot)
            @ scale
            @ _translation(-scale_pivot)
        )
        return cls(int(model.values()[0]), props, order, before, after)

    def matrix(self, translation: np.ndarray, angles: np.ndarray) -> np.ndarray:
        return _compose([self], translation[:, None], angles[:, None])[:, 0]


def _compose(nodes: list[_Node], translation: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The nodes' local matrices (F, J, 4, 4) from ``Lcl Translation`` and ``Lcl Rotation``
    (F, J, 3 each; degrees), one rotation call per rotation order."""
    rotations = np.empty(angles.shape[:2] + (4, 4))
    for order in {n.order for n in nodes}:
        group = [k for k, n in enumerate(nodes) if n.order == order]
        rotations[:, group] = _rotation(angles[:, group], order)
    before = np.array([n.before for n in nodes])
    after = np.array([n.after for n in nodes])
    return _translation(translation) @ before @ rotations @ after


def _solve(nodes: list[_Node], local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Lcl Translation`` and ``Lcl Rotation`` (degrees, X Y Z, continuous over the frames),
    each ``(F, J, 3)``, that give the nodes' local matrices ``local`` (F, J, 4, 4)."""
    before = np.array([n.before for n in nodes])
    after = np.array([n.after for n in nodes])
    rot = np.linalg.inv(before[:, :3, :3]) @ local[..., :3, :3] @ np.linalg.inv(after[:, :3, :3])
    frames = len(local)
    xyz = np.empty(local.shape[:2] + (3,))
    for order in {n.order for n in nodes}:
        group = [k for k, n in enumerate(nodes) if n.order == order]
        seq = Rotation.from_matrix(rot[:, group].reshape(-1, 3, 3)).as_euler(order)
        seq = _continuous(seq.reshape(frames, len(group), 3))
        xyz[:, group] = np.degrees(seq[..., [order.index(a) for a in "xyz"]])
    composed = _compose(nodes, np.zeros(xyz.shape), xyz)
    return local[..., :3, 3] - composed[..., :3, 3], xyz


def _continuous(angles: np.ndarray) -> np.ndarray:
    """Euler angles (F, J, 3, in a sequence's order, radians) with each frame's chosen among
    its two equivalent sets (``a + pi, pi - b, c + pi``) and its multiples of 2 pi as the
    closest to the frame before, so curves do not flip between frames."""
    other = angles + np.array([np.pi, 0.0, np.pi])
    other[..., 1] = np.pi - angles[..., 1]
    out = angles.copy()
    for f in range(1, len(angles)):
        prev = out[f - 1]
        near = [c - 2 * np.pi * np.round((c - prev) / (2 * np.pi)) for c in (angles[f], other[f])]
        gap = [np.abs(c - prev).sum(axis=-1, keepdims=True) for c in near]
        out[f] = np.where(gap[1] < gap[0], near[1], near[0])
    return out


class Plan:
    """How to key a new animation into one FBX file (from :func:`plan`)."""

    def __init__(
        self,
        document: B.Document,
        nodes: list[_Node],
        roots: dict[int, np.ndarray],
        held: dict[int, float],
        parents: np.ndarray,
        start: int,
        fps: float,
    ) -> None:
        self.document = document
        self.nodes = nodes
        self.roots = roots  # root bone index -> its fixed matrix
        self.held = held  # constant curves above the bones (their ids -> values)
        self.parents = parents
        self.start = start  # ticks of the file's first frame
        self.fps = fps

    def write(self, pose: np.ndarray, fps: float) -> bytes:
        """The file with ``pose`` (F, J, 4, 4 armature-space bone matrices, bones in the order
        :func:`plan` was given) keyed at ``fps`` from the file's first frame."""
        doc = self.document
        frames = len(pose)
        times = self.start + np.round(np.arange(frames) * TICKS_PER_SECOND / fps).astype(np.int64)
        parents = self.parents
        local = np.empty_like(pose)
        child = parents >= 0
        local[:, child] = np.linalg.inv(pose[:, parents[child]]) @ pose[:, child]
        for k, fixed in self.roots.items():
            local[:, k] = fixed @ pose[:, k]
        objects, connections = doc.node(b"Objects"), doc.node(b"Connections")
        layer = next(o for o in objects.children if o.name == b"AnimationLayer")
        layer_id = layer.values()[0]
        ends = times[[0, -1]]
        objects.children = [
            _curve(o.values()[0], ends, np.full(2, self.held[o.values()[0]]))
            if o.name == b"AnimationCurve" and o.values()[0] in self.held
            else o
            for o in objects.children
        ]
        used = {o.values()[0] for o in objects.children}
        fresh = _ids(used)
        added_nodes, added_curves = [], 0
        translations, rotations = _solve(self.nodes, local)
        for k, node in enumerate(self.nodes):
            for label, prop, values in (
                (b"T", b"Lcl Translation", translations[:, k]),
                (b"R", b"Lcl Rotation", rotations[:, k]),
            ):
                if self.parents[k] >= 0 and _holds(values, node.props.get(prop)):
                    continue  # the node's own value all along (a bone's offset): no curves;
                    # root bones are always keyed, so the take keeps its length
                curve_node = next(fresh)
                p70 = [
                    B.Node.make(b"P", c, b"Number", b"", b"A", float(values[0, i]))
                    for i, c in enumerate(CHANNELS)
                ]
                objects.children.append(
                    B.Node.make(
                        b"AnimationCurveNode",
                        curve_node,
                        label + b"\x00\x01AnimCurveNode",
                        b"",
                        children=[B.Node.make(b"Properties70", children=p70)],
                    )
                )
                connections.children += [
                    B.Node.make(b"C", b"OO", curve_node, layer_id),
                    B.Node.make(b"C", b"OP", curve_node, node.id, prop),
                ]
                added_nodes.append(curve_node)
                for i, channel in enumerate(CHANNELS):
                    curve = next(fresh)
                    objects.children.append(_curve(curve, times, values[:, i]))
                    connections.children.append(
                        B.Node.make(b"C", b"OP", curve, curve_node, channel)
                    )
                    added_curves += 1
        _count(doc, b"AnimationCurveNode", len(added_nodes))
        _count(doc, b"AnimationCurve", added_curves)
        _time_span(doc, int(times[0]), int(times[-1]), fps, self.fps)
        return B.dumps(doc)


def _holds(values: np.ndarray, static: list | None) -> bool:
    """Whether every frame of ``values`` (F, 3) is the node's static value ``static``."""
    if static is None or len(static) < 3:
        return False
    scale = max(1.0, float(np.abs(values).max()))
    return bool(np.abs(values - np.asarray(static[:3], dtype=np.float64)).max() <= 1e-5 * scale)


def _ids(used: set[int]):
    """Object ids not in ``used`` (FBX ids are positive 64-bit integers)."""
    candidate = max(used, default=0)
    while True:
        candidate = candidate + 1 if candidate < (1 << 62) else 1
        if candidate not in used:
            used.add(candidate)
            yield candidate


def _curve(curve_id: int, times: np.ndarray, values: np.ndarray) -> B.Node:
    values = values.astype(np.float32)
    if len(times) > 1 and np.ptp(values) <= 1e-6 * max(1.0, float(np.abs(values).max())):
        times, values = times[[0, -1]], values[[0, -1]]  # constant: its ends only
    version, flags, data = _CURVE_NODES
    return B.Node.make(
        b"AnimationCurve",
        curve_id,
        b"\x00\x01AnimCurve",
        b"",
        children=[
            B.Node.make(b"Default", float(values[0])),
            version,
            B.Node.make(b"KeyTime", times),
            B.Node.make(b"KeyValueFloat", values),
            flags,
            data,
            B.Node.make(b"KeyAttrRefCount", np.array([len(times)], dtype=np.int32)),
        ],
    )


# the same in every curve (nodes are written, never changed, so they can be shared)
_CURVE_NODES = (
    B.Node.make(b"KeyVer", B.Int32(4008)),
    B.Node.make(b"KeyAttrFlags", _KEY_FLAGS),
    B.Node.make(b"KeyAttrDataFloat", _KEY_DATA),
)


def _count(doc: B.Document, kind: bytes, delta: int) -> None:
    """Definitions' object count of ``kind`` and the total moved by ``delta``."""
    definitions = doc.node(b"Definitions")
    for node in [
        definitions,
        *(t for t in definitions.all(b"ObjectType") if t.values()[0] == kind),
    ]:
        count = node.child(b"Count")
        if count is not None:
            count.set(0, int(count.values()[0]) + delta)


def _set_p(props: B.Node, name: bytes, kind: tuple[bytes, bytes, bytes], value) -> None:
    for p in props.children:
        if p.values()[0] == name:
            p.set(4, value)
            return
    props.children.append(B.Node.make(b"P", name, *kind, value))


def _time_span(doc: B.Document, start: int, stop: int, fps: float, file_fps: float) -> None:
    ktime = (b"KTime", b"Time", b"")
    stack = next(o for o in doc.node(b"Objects").children if o.name == b"AnimationStack")
    p70 = stack.child(b"Properties70")
    if p70 is None:
        p70 = B.Node.make(b"Properties70")
        p70.block = True
        stack.children.append(p70)
    for name, value in (
        (b"LocalStart", start),
        (b"LocalStop", stop),
        (b"ReferenceStart", start),
        (b"ReferenceStop", stop),
    ):
        _set_p(p70, name, ktime, value)
    settings = doc.node(b"GlobalSettings").child(b"Properties70")
    _set_p(settings, b"TimeSpanStart", ktime, start)
    _set_p(settings, b"TimeSpanStop", ktime, stop)
    if abs(fps - file_fps) > 1e-6 * fps:
        _set_p(settings, b"TimeMode", (b"enum", b"", b""), _CUSTOM)
        _set_p(settings, b"CustomFrameRate", (b"double", b"Number", b""), float(fps))
    takes = next((n for n in doc.nodes if n.name == b"Takes"), None)
    for take in takes.all(b"Take") if takes is not None else ():
        for name in (b"LocalTime", b"ReferenceTime"):
            span = take.child(name)
            if span is not None and span.count == 2:
                span.set(0, start)
                span.set(1, stop)


def file_fps(doc: B.Document) -> float | None:
    settings = _props(doc.node(b"GlobalSettings"))
    mode = int(settings.get(b"TimeMode", [0])[0])
    if mode == _CUSTOM:
        return float(settings.get(b"CustomFrameRate", [0.0])[0]) or None
    return _TIME_MODES.get(mode)


def plan(data: bytes, names: tuple[str, ...], parents: np.ndarray, first: np.ndarray) -> Plan | str:
    """How to key new poses into FBX ``data``, whose armature Blender read as bones ``names``
    (parents first, ``parents``) with armature-space matrices ``first`` (J, 4, 4) on the
    file's first animated frame; or why it cannot be done here (a sentence)."""
    try:
        return _plan(data, names, np.asarray(parents), np.asarray(first, dtype=np.float64))
    except MotionError as exc:
        return exc.message


def _plan(
    data: bytes, names: tuple[str, ...], parents: np.ndarray, first: np.ndarray
) -> Plan | str:
    doc = B.loads(data)
    if doc.version >= 8000:
        return "FBX 8 files keep time in other units"
    objects = doc.node(b"Objects").children
    stacks = [o for o in objects if o.name == b"AnimationStack"]
    layers = [o for o in objects if o.name == b"AnimationLayer"]
    if len(stacks) != 1 or len(layers) != 1:
        return f"the file has {len(stacks)} animation stacks and {len(layers)} layers, not one"
    fps = file_fps(doc)
    if fps is None:
        return "the file's frame rate is not one this writer knows"
    by_id = {int(o.values()[0]): o for o in objects}
    models: dict[str, list[B.Node]] = {}
    for o in objects:
        if o.name == b"Model":
            models.setdefault(
                o.values()[1].split(b"\x00\x01")[0].decode("utf-8", "replace"), []
            ).append(o)
    parent_of: dict[int, int] = {}
    attached: dict[int, list[tuple[int, bytes]]] = {}  # object -> (curve node or curve, prop)
    for c in doc.node(b"Connections").children:
        v = c.values()
        is_model = [int(i) in by_id and by_id[int(i)].name == b"Model" for i in v[1:3]]
        if v[0] == b"OO" and is_model[0] and (is_model[1] or int(v[2]) == 0):
            parent_of[int(v[1])] = int(v[2])  # (a bone is also a child of its skin clusters)
        elif v[0] == b"OP" and int(v[1]) in by_id and len(v) > 3:
            attached.setdefault(int(v[2]), []).append((int(v[1]), v[3]))
    template = {}
    for t in doc.node(b"Definitions").all(b"ObjectType"):
        if t.values()[0] == b"Model":
            template = _props(t.child(b"PropertyTemplate"))
    nodes: list[_Node] = []
    for name in names:
        found = models.get(name, [])
        if len(found) != 1:
            return f"bone {name!r} is not one FBX node of that name"
        nodes.append(_Node.of(found[0], template))
    ids = [n.id for n in nodes]
    # the curves on the bones' first frame, and nothing animated above the root bones
    curve_nodes = {i: attached.get(i, []) for i in ids}
    start = min(
        (
            int(_curve_keys(by_id[cv])[0][0])
            for i in ids
            for cn, _ in curve_nodes[i]
            for cv, _ in attached.get(cn, [])
            if by_id.get(cv) is not None and by_id[cv].name == b"AnimationCurve"
        ),
        default=None,
    )
    if start is None:
        return "the bones have no animation curves"
    size = max(float(np.abs(first[:, :3, 3]).max()), 1e-9)
    roots: dict[int, np.ndarray] = {}
    held: dict[int, float] = {}  # constant curves above the bones: id -> value
    file_values: list[tuple[np.ndarray, np.ndarray]] = []  # each bone's T and R, first frame
    for k, node in enumerate(nodes):
        values = {}
        for prop, default in ((b"Lcl Translation", 0.0), (b"Lcl Rotation", 0.0)):
            value = np.array(node.props.get(prop, [default] * 3)[:3], dtype=np.float64)
            for cn, cn_prop in curve_nodes[node.id]:
                if cn_prop != prop:
                    continue
                for cv, channel in attached.get(cn, []):
                    if channel in CHANNELS and cv in by_id:
                        times, keys = _curve_keys(by_id[cv])
                        at = np.searchsorted(times, start)
                        if at < len(times) and times[at] != start:
                            return f"bone {names[k]!r} has no key on the first frame"
                        value[CHANNELS.index(channel)] = keys[min(at, len(keys) - 1)]
            values[prop] = value
        if any(p == b"Lcl Scaling" for _, p in curve_nodes[node.id]):
            scaled = [
                cv
                for cn, p in curve_nodes[node.id]
                if p == b"Lcl Scaling"
                for cv, _ in attached.get(cn, [])
                if cv in by_id
            ]
            if any(np.abs(_curve_keys(by_id[cv])[1] - 1.0).max() > TOLERANCE for cv in scaled):
                return f"bone {names[k]!r} is scaled by its animation"
        file_values.append((values[b"Lcl Translation"], values[b"Lcl Rotation"]))
        if parents[k] >= 0:
            if parent_of.get(node.id) != nodes[parents[k]].id:
                return f"bone {names[k]!r} has another parent in the FBX file than in Blender"
        else:
            above = parent_of.get(node.id, 0)
            while above in by_id:  # keyed, maybe, but not moving: left as it is
                for cn, _ in attached.get(above, []):
                    for cv, _ in attached.get(cn, []):
                        if cv not in by_id:
                            continue
                        keys = _curve_keys(by_id[cv])[1]
                        if np.ptp(keys) > 1e-6 * max(1.0, float(np.abs(keys).max())):
                            return f"a node above bone {names[k]!r} is animated"
                        held[cv] = float(keys[0])  # retimed to the new span
                above = parent_of.get(above, 0)
    translation, angles = (np.array(v)[None] for v in zip(*file_values, strict=True))
    local = _compose(nodes, translation, angles)[0]  # (J, 4, 4) as the file has them
    child = parents >= 0
    read = np.linalg.inv(first[parents[child]]) @ first[child]  # as Blender read them
    gap_t = np.abs(local[child, :3, 3] - read[:, :3, 3]).max(axis=-1) > TOLERANCE * size
    gap_r = np.abs(local[child, :3, :3] - read[:, :3, :3]).max(axis=(-2, -1)) > TOLERANCE
    if (gap_t | gap_r).any():
        k = np.flatnonzero(child)[np.argmax(gap_t | gap_r)]
        return f"bone {names[k]!r}'s FBX transform is not the one Blender read"
    for k in np.flatnonzero(~child):
        roots[int(k)] = local[k] @ np.linalg.inv(first[k])
    removed = {cn for i in ids for cn, _ in curve_nodes[i]}
    removed |= {cv for cn in removed for cv, _ in attached.get(cn, [])}
    _remove(doc, removed)
    return Plan(doc, nodes, roots, held, parents, start, fps)


def _curve_keys(curve: B.Node) -> tuple[np.ndarray, np.ndarray]:
    times, values = curve.child(b"KeyTime"), curve.child(b"KeyValueFloat")
    if times is None or values is None:
        raise MotionError("an animation curve has no keys")
    t, v = times.values()[0], values.values()[0]
    if not len(t) or len(t) != len(v):
        raise MotionError("an animation curve's keys and values disagree")
    return t, v.astype(np.float64)


def _remove(doc: B.Document, ids: set[int]) -> None:
    """Objects ``ids`` and every connection to or from them leave the file."""
    objects, connections = doc.node(b"Objects"), doc.node(b"Connections")
    kinds = {o.name: 0 for o in objects.children}
    kept = []
    for o in objects.children:
        if o.values()[0] in ids:
            kinds[o.name] -= 1
        else:
            kept.append(o)
    objects.children = kept
    connections.children = [
        c for c in connections.children if not ({c.values()[1], c.values()[2]} & ids)
    ]
    for kind, delta in kinds.items():
        if delta:
            _count(doc, kind, delta)

"""Writing a new animation into a parsed glTF document (:mod:`motion.gltf`): new samplers
and channels in the accessors and buffer views the old ones used alone, so that a file
restyled twice does not grow, then the GLB packed with every other node, mesh, skin,
material and animation kept.
"""

from __future__ import annotations

import json
import warnings

import numpy as np

from motion.gltf_container import FLOAT_COMPONENT, GltfDocument


class AnimationWriter:
    """Puts new samplers and channels into one animation of a document and packs the GLB."""

    def __init__(self, doc: GltfDocument, animation: int | None) -> None:
        self.doc = doc
        self.gltf = doc.gltf
        self.animation = animation

    def write(self, times: np.ndarray, outputs: list[tuple[int, str, np.ndarray]]) -> bytes:
        from pygltflib import (
            Animation,
            AnimationChannel,
            AnimationChannelTarget,
            AnimationSampler,
            Buffer,
        )

        gltf = self.gltf
        free_accessors, free_views = self._exclusive_to_animation()
        blob = bytearray()
        views: list[tuple[int, int]] = []  # (start, length) in the blob of each new view
        for i, data in enumerate(self.doc.buffers):  # every buffer into one, views moved along
            _pad(blob)
            base = len(blob)
            blob += data
            for view in gltf.bufferViews or []:
                if view.buffer == i:
                    view.buffer = 0
                    view.byteOffset = (view.byteOffset or 0) + base
        arrays = [times[:, None]] + [values.astype(np.float32) for _, _, values in outputs]
        for array in arrays:
            _pad(blob)
            views.append((len(blob), array.nbytes))
            blob += np.ascontiguousarray(array, dtype="<f4").tobytes()
        accessors = [
            self._put_view_and_accessor(start, length, array, free_accessors, free_views)
            for (start, length), array in zip(views, arrays, strict=True)
        ]
        self._stub_leftovers(free_accessors, free_views, blob)
        samplers = [
            AnimationSampler(input=accessors[0], output=acc, interpolation="LINEAR")
            for acc in accessors[1:]
        ]
        channels = [
            AnimationChannel(sampler=k, target=AnimationChannelTarget(node=node, path=path))
            for k, (node, path, _) in enumerate(outputs)
        ]
        if self.animation is None:
            gltf.animations = (gltf.animations or []) + [Animation(name="motion-style")]
            self.animation = len(gltf.animations) - 1
        animation = gltf.animations[self.animation]
        animation.samplers = samplers
        animation.channels = channels
        gltf.buffers = [Buffer(byteLength=len(blob))]
        gltf.set_binary_blob(bytes(blob))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return b"".join(gltf.save_to_bytes())

    def _exclusive_to_animation(self) -> tuple[list[int], list[int]]:
        """Accessors and buffer views that only the replaced animation uses (ascending)."""
        gltf = self.gltf
        if self.animation is None:
            return [], []
        old = gltf.animations[self.animation]
        mine = {s.input for s in old.samplers or []} | {s.output for s in old.samplers or []}
        others: set = set()
        document = json.loads(gltf.gltf_to_json())  # to_dict() is 3x slower
        for k, anim in enumerate(document.get("animations", [])):
            if k != self.animation:
                _collect_accessor_refs(anim, others)
        for key, value in document.items():
            if key not in ("animations", "accessors", "bufferViews", "buffers"):
                _collect_accessor_refs(value, others)
        accessors = sorted(
            a for a in mine if isinstance(a, int) and a not in others
            and 0 <= a < len(gltf.accessors or [])
        )  # fmt: skip
        used_views: dict[int, set[int]] = {}
        for a, acc in enumerate(gltf.accessors or []):
            refs = [acc.bufferView]
            if acc.sparse is not None:
                refs += [acc.sparse.indices.bufferView, acc.sparse.values.bufferView]
            for v in refs:
                if v is not None:
                    used_views.setdefault(v, set()).add(a)
        outside: set = set()
        for key, value in document.items():
            if key not in ("accessors", "bufferViews", "buffers", "animations"):
                _collect_keyed(value, "bufferView", outside)
        views = sorted(
            v for v, users in used_views.items()
            if users <= set(accessors) and v not in outside
        )  # fmt: skip
        return accessors, views

    def _put_view_and_accessor(self, start, length, array, free_accessors, free_views) -> int:
        from pygltflib import Accessor, BufferView

        gltf = self.gltf
        view = BufferView(buffer=0, byteOffset=start, byteLength=length)
        if free_views:
            v = free_views.pop(0)
            gltf.bufferViews[v] = view
        else:
            gltf.bufferViews = (gltf.bufferViews or []) + [view]
            v = len(gltf.bufferViews) - 1
        width = array.shape[1]
        accessor = Accessor(
            bufferView=v,
            byteOffset=0,
            componentType=FLOAT_COMPONENT,
            count=int(array.shape[0]),
            type="SCALAR" if width == 1 else f"VEC{width}",
            min=[float(x) for x in array.min(axis=0)],
            max=[float(x) for x in array.max(axis=0)],
        )
        if free_accessors:
            a = free_accessors.pop(0)
            gltf.accessors[a] = accessor
        else:
            gltf.accessors = (gltf.accessors or []) + [accessor]
            a = len(gltf.accessors) - 1
        return a

    def _stub_leftovers(self, free_accessors, free_views, blob: bytearray) -> None:
        """Old accessors and views nothing uses any more become 4-byte stubs (indices stay)."""
        from pygltflib import Accessor, BufferView

        if not free_accessors and not free_views:
            return
        _pad(blob)
        start = len(blob)
        blob += np.zeros(1, "<f4").tobytes()
        for v in free_views:
            self.gltf.bufferViews[v] = BufferView(buffer=0, byteOffset=start, byteLength=4)
        stub_view = free_views[0] if free_views else None
        if stub_view is None and free_accessors:
            self.gltf.bufferViews.append(BufferView(buffer=0, byteOffset=start, byteLength=4))
            stub_view = len(self.gltf.bufferViews) - 1
        for a in free_accessors:
            self.gltf.accessors[a] = Accessor(
                bufferView=stub_view, componentType=FLOAT_COMPONENT, count=1, type="SCALAR",
                min=[0.0], max=[0.0],
            )  # fmt: skip


def _pad(blob: bytearray) -> None:
    blob += b"\0" * (-len(blob) % 8)


_ACCESSOR_KEYS = ("indices", "inverseBindMatrices", "input", "output", "accessor")


def _collect_accessor_refs(value, out: set, key: str | None = None, in_attributes=False) -> None:
    """Integers a glTF JSON subtree uses as accessor indices (core and the usual extensions)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _collect_accessor_refs(v, out, k, in_attributes or k in ("attributes", "targets"))
    elif isinstance(value, list):
        for v in value:
            _collect_accessor_refs(v, out, key, in_attributes)
    elif isinstance(value, int) and not isinstance(value, bool):
        if in_attributes or key in _ACCESSOR_KEYS:
            out.add(value)


def _collect_keyed(value, name: str, out: set) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            if k == name and isinstance(v, int):
                out.add(v)
            else:
                _collect_keyed(v, name, out)
    elif isinstance(value, list):
        for v in value:
            _collect_keyed(v, name, out)

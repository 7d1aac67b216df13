"""The glTF container as :mod:`motion.gltf` reads it: the document parsed by pygltflib, its
buffers' bytes (embedded only, never a file path), and accessors unpacked into numpy arrays
(pygltflib leaves that out). Every problem of a malformed file is a
:class:`~motion.errors.MotionError` naming it.
"""

from __future__ import annotations

import base64
import binascii
import warnings
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from motion.errors import MotionError

_MAX_VALUES = 50_000_000  # elements of one accessor: far beyond any real clip


FLOAT_COMPONENT = 5126
_COMPONENTS = {  # componentType -> (numpy dtype, divisor when normalized)
    5120: (np.dtype("i1"), 127.0),
    5121: (np.dtype("u1"), 255.0),
    5122: (np.dtype("<i2"), 32767.0),
    5123: (np.dtype("<u2"), 65535.0),
    5125: (np.dtype("<u4"), None),
    FLOAT_COMPONENT: (np.dtype("<f4"), None),
}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


@contextmanager
def malformed_as_motion_error() -> Iterator[None]:
    """pygltflib fills its objects from JSON unchecked: a member of the wrong type (a node
    where a list belongs, a string where a number does) surfaces as a Python error deep in
    the reading. Each is a malformed file, reported as such."""
    try:
        yield
    except MotionError:
        raise
    except (AttributeError, TypeError, KeyError, IndexError, ValueError, OverflowError) as exc:
        raise MotionError(f"the glTF file is malformed: {error_reason(exc)}") from None


class GltfDocument:
    """A parsed glTF document and its buffers' bytes (embedded only: never a file path)."""

    def __init__(self, data: bytes) -> None:
        from pygltflib import GLTF2

        if not isinstance(data, bytes | bytearray | memoryview):
            raise MotionError("a glTF file must be given as bytes")
        data = bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if data[:4] == b"glTF":
                    gltf = GLTF2.load_from_bytes(data)
                    if gltf is None:
                        raise ValueError("no JSON chunk")
                else:
                    gltf = GLTF2.gltf_from_json(data.decode("utf-8-sig"))
        except MotionError:
            raise
        except Exception as exc:  # pygltflib raises whatever its parsers raise
            raise MotionError(f"not a readable glTF file: {error_reason(exc)}") from None
        version = str(getattr(gltf.asset, "version", "") or "")
        if not version.startswith("2."):
            raise MotionError(f"glTF version {version or '(none)'} is not supported; 2.0 is")
        self.gltf = gltf
        self.buffers: list[bytes] = []
        for i, buffer in enumerate(gltf.buffers or []):
            self.buffers.append(self._buffer_bytes(i, buffer))

    def _buffer_bytes(self, i: int, buffer) -> bytes:
        uri = buffer.uri
        if uri is None:
            blob = self.gltf.binary_blob()
            if i != 0 or blob is None:
                raise MotionError(f"buffer {i} has no data: the GLB has no binary chunk for it")
            data = bytes(blob)
        elif uri.startswith("data:"):
            header, _, payload = uri.partition(",")
            if not header.endswith(";base64"):
                raise MotionError(f"buffer {i}: only base64 data URIs are supported")
            try:
                data = base64.b64decode(payload, validate=False)
            except (binascii.Error, ValueError):
                raise MotionError(f"buffer {i}: its data URI is not valid base64") from None
        else:
            raise MotionError(
                f"buffer {i} refers to an external file ({uri[:60]!r}): send a .glb, or a "
                ".gltf with its buffers embedded"
            )
        length = buffer.byteLength or 0
        if len(data) < length:
            raise MotionError(f"buffer {i} holds {len(data)} bytes, its byteLength says {length}")
        return data

    def item(self, kind: str, index, what: str):
        items = getattr(self.gltf, kind) or []
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise MotionError(f"{what} refers to {kind[:-1]} {index!r}, which does not exist")
        return items[index]

    def accessor(self, index: int, what: str) -> np.ndarray:
        """An accessor's elements as float64 ``(count, width)`` (normalized ints scaled)."""
        acc = self.item("accessors", index, what)
        width = _WIDTHS.get(acc.type)
        if width is None:
            raise MotionError(f"{what}: accessor {index} is {acc.type!r}, not a scalar or vector")
        if acc.componentType not in _COMPONENTS:
            raise MotionError(f"{what}: accessor {index} has component type {acc.componentType}")
        dtype, norm = _COMPONENTS[acc.componentType]
        count = acc.count
        if not isinstance(count, int) or count < 1 or count * width > _MAX_VALUES:
            raise MotionError(f"{what}: accessor {index} has an unusable count {count!r}")
        if acc.bufferView is None:
            out = np.zeros((count, width), dtype=np.float64)
        else:
            raw = self._view_elements(
                acc.bufferView, acc.byteOffset or 0, count, width, dtype, what
            )
            out = raw.astype(np.float64)
        if acc.sparse is not None:
            sp = acc.sparse
            n = sp.count
            if not isinstance(n, int) or not 1 <= n <= count:
                raise MotionError(f"{what}: accessor {index} has a sparse count {n!r}")
            itype = _COMPONENTS.get(sp.indices.componentType, (None,))[0]
            if itype is None or itype.kind != "u":
                raise MotionError(f"{what}: accessor {index} has sparse indices that are not ints")
            idx = self._view_elements(
                sp.indices.bufferView, sp.indices.byteOffset or 0, n, 1, itype, what
            )[:, 0].astype(np.int64)
            if idx.max() >= count:
                raise MotionError(f"{what}: accessor {index} has a sparse index past its end")
            vals = self._view_elements(
                sp.values.bufferView, sp.values.byteOffset or 0, n, width, dtype, what
            )
            out[idx] = vals
        if norm is not None and acc.normalized:
            out = np.maximum(out / norm, -1.0)
        if not np.isfinite(out).all():
            raise MotionError(f"{what}: accessor {index} holds values that are not finite")
        return out

    def _view_elements(self, view_index, offset, count, width, dtype, what) -> np.ndarray:
        view = self.item("bufferViews", view_index, what)
        self.item("buffers", view.buffer, f"buffer view {view_index}")
        buffer = self.buffers[view.buffer]
        size = dtype.itemsize * width
        stride = view.byteStride or size
        start = (view.byteOffset or 0) + offset
        end = start + stride * (count - 1) + size
        view_end = (view.byteOffset or 0) + (view.byteLength or 0)
        if offset < 0 or stride < size or end > view_end or view_end > len(buffer):
            raise MotionError(f"{what}: its data runs past buffer view {view_index}")
        arr = np.ndarray((count, width), dtype, buffer, start, (stride, dtype.itemsize))
        return arr.copy()


def error_reason(exc: Exception) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]

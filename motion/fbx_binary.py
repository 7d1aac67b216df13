"""Binary FBX (7.x) as a tree of nodes that can be changed and written back, everything not
changed kept byte for byte: a node's properties stay the raw bytes they were read as
(arrays stay compressed) until :meth:`Node.values` decodes them, and :func:`dumps` only
recomputes the end offsets every node header holds.

The format, as Blender's ``io_scene_fbx`` (``parse_fbx``, ``encode_bin``) reads and writes
it: a 27-byte header, then nodes ``(end offset, property count, property bytes, name)``
(32-bit fields before version 7500, 64-bit from it), each with its properties (a type byte
then the value: ``Y C I F D L`` scalars, ``S R`` length-prefixed bytes, ``f d l i b``
arrays, optionally zlib-compressed) and its children closed by a zero record; after the
top-level zero record a footer whose first 16 bytes and layout are kept.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from motion.errors import MotionError

MAGIC = b"Kaydara FBX Binary  \x00\x1a\x00"
_SCALARS = {b"Y": "<h", b"C": "<?", b"I": "<i", b"F": "<f", b"D": "<d", b"L": "<q"}
_ARRAYS = {b"f": np.float32, b"d": np.float64, b"l": np.int64, b"i": np.int32, b"b": np.bool_}
_COMPRESS_FROM = 128  # array bytes from which an array is written compressed (as Blender does)


@dataclass(eq=False)
class Node:
    """One node: ``name``, its properties as raw bytes (``count`` of them), its children,
    and whether it ends with a zero record (``block``: some nodes have one without
    children)."""

    name: bytes
    raw: bytes = b""
    count: int = 0
    children: list[Node] = field(default_factory=list)
    block: bool = False
    _values: list | None = field(default=None, repr=False)

    @classmethod
    def make(cls, name: bytes | str, *values, children: list[Node] | None = None) -> Node:
        """A new node with ``values`` as its properties (types as :func:`encode` picks)."""
        name = name.encode() if isinstance(name, str) else name
        kids = list(children or [])
        return cls(name, b"".join(encode(v) for v in values), len(values), kids, bool(kids))

    def values(self) -> list:
        """The properties decoded: numbers, bytes, numpy arrays (decoded once)."""
        if self._values is None:
            self._values = [value for _, value in self._decoded()]
        return self._values

    def set(self, index: int, value) -> None:
        """Property ``index`` becomes ``value``, written with the type it had."""
        decoded = self._decoded()
        kind = decoded[index][0]
        decoded[index] = (kind, value)
        self.raw = b"".join(_encode_as(k, v) for k, v in decoded)
        self._values = None

    def _decoded(self) -> list[tuple[bytes, object]]:
        out, pos, raw = [], 0, self.raw
        for _ in range(self.count):
            kind = raw[pos : pos + 1]
            pos += 1
            if kind in _SCALARS:
                fmt = _SCALARS[kind]
                (value,) = struct.unpack_from(fmt, raw, pos)
                pos += struct.calcsize(fmt)
            elif kind in (b"S", b"R"):
                (size,) = struct.unpack_from("<I", raw, pos)
                value = bytes(raw[pos + 4 : pos + 4 + size])
                pos += 4 + size
            elif kind in _ARRAYS:
                length, encoding, size = struct.unpack_from("<III", raw, pos)
                payload = raw[pos + 12 : pos + 12 + size]
                pos += 12 + size
                if encoding == 1:
                    payload = zlib.decompress(payload)
                value = np.frombuffer(payload, dtype=_ARRAYS[kind], count=length).copy()
            else:
                raise MotionError(f"FBX property of unknown type {kind!r}")
            out.append((kind, value))
        return out

    def child(self, name: bytes) -> Node | None:
        return next((c for c in self.children if c.name == name), None)

    def all(self, name: bytes) -> list[Node]:
        return [c for c in self.children if c.name == name]


class Int32(int):
    """An ``I`` property (plain ints are written as ``L``)."""


class Int16(int):
    """A ``Y`` property."""


def _encode_as(kind: bytes, value) -> bytes:
    if kind in _SCALARS:
        return kind + struct.pack(_SCALARS[kind], value)
    if kind in (b"S", b"R"):
        return kind + struct.pack("<I", len(value)) + value
    return encode(np.asarray(value, dtype=_ARRAYS[kind]))


def encode(value) -> bytes:
    """One property: bool ``C``, :class:`Int16` ``Y``, :class:`Int32` ``I``, int ``L``,
    float ``D``, bytes/str ``S``, numpy arrays ``f d l i b`` by dtype."""
    if isinstance(value, (bool, np.bool_)):
        return b"C" + struct.pack("<?", bool(value))
    if isinstance(value, Int16):
        return b"Y" + struct.pack("<h", value)
    if isinstance(value, Int32):
        return b"I" + struct.pack("<i", value)
    if isinstance(value, (int, np.integer)):
        return b"L" + struct.pack("<q", int(value))
    if isinstance(value, (float, np.floating)):
        return b"D" + struct.pack("<d", float(value))
    if isinstance(value, str):
        value = value.encode()
    if isinstance(value, bytes):
        return b"S" + struct.pack("<I", len(value)) + value
    if isinstance(value, np.ndarray):
        kind = next((k for k, t in _ARRAYS.items() if value.dtype == t), None)
        if kind is None or value.ndim != 1:
            raise ValueError(f"no FBX array type for {value.dtype} {value.shape}")
        payload = np.ascontiguousarray(value).tobytes()
        encoding = 0
        if len(payload) >= _COMPRESS_FROM:
            payload, encoding = zlib.compress(payload, 1), 1
        return kind + struct.pack("<III", len(value), encoding, len(payload)) + payload
    raise ValueError(f"no FBX property type for {type(value).__name__}")


@dataclass(eq=False)
class Document:
    """A parsed file: its ``version``, top-level ``nodes`` and the footer's first 16 bytes."""

    version: int
    nodes: list[Node]
    footer_id: bytes

    def node(self, name: bytes) -> Node:
        found = next((n for n in self.nodes if n.name == name), None)
        if found is None:
            raise MotionError(f"the FBX file has no {name.decode()} section")
        return found


def _header(version: int) -> tuple[str, int]:
    return ("<QQQB", 25) if version >= 7500 else ("<IIIB", 13)


def loads(data: bytes) -> Document:
    """Parse binary FBX ``data`` (the properties are not decoded)."""
    if not data.startswith(MAGIC) or len(data) < 27:
        raise MotionError("not a binary FBX file")
    (version,) = struct.unpack_from("<I", data, 23)
    fmt, size = _header(version)
    view = memoryview(data)

    def read_list(pos: int, stop: int | None) -> tuple[list[Node], int]:
        nodes = []
        while stop is None or pos < stop:
            end, count, plen, nlen = struct.unpack_from(fmt, data, pos)
            if end == 0:  # the zero record closing this list
                return nodes, pos + size
            start = pos + size + nlen
            node = Node(bytes(view[pos + size : start]), bytes(view[start : start + plen]), count)
            body = start + plen
            if end > body:
                node.children, _ = read_list(body, end - size)
                node.block = True
            nodes.append(node)
            pos = end
        return nodes, pos + size

    try:
        nodes, pos = read_list(27, None)
    except struct.error:
        raise MotionError("the FBX file is truncated") from None
    return Document(version, nodes, bytes(view[pos : pos + 16]))


def dumps(document: Document) -> bytes:
    """The file: header, nodes with their end offsets recomputed, zero record, footer."""
    fmt, size = _header(document.version)
    zero = b"\0" * size
    chunks: list[bytes] = [MAGIC, struct.pack("<I", document.version)]

    def length(node: Node) -> int:
        total = size + len(node.name) + len(node.raw)
        if node.children or node.block:
            total += sum(length(c) for c in node.children) + size
        node._length = total
        return total

    def write(node: Node, offset: int) -> int:
        end = offset + node._length
        chunks.append(struct.pack(fmt, end, node.count, len(node.raw), len(node.name)))
        chunks.extend((node.name, node.raw))
        offset += size + len(node.name) + len(node.raw)
        if node.children or node.block:
            for c in node.children:
                offset = write(c, offset)
            chunks.append(zero)
            offset += size
        return offset

    offset = 27
    for node in document.nodes:
        length(node)
        offset = write(node, offset)
    chunks.append(zero)
    offset += size
    # footer, as Blender writes it (its id kept): id, 4 zeros, padding to 16 (16 when
    # aligned), the version, 120 zeros, the closing magic
    offset += 20
    pad = ((offset + 15) & ~15) - offset or 16
    chunks += [document.footer_id, b"\0" * (4 + pad), struct.pack("<I", document.version)]
    chunks += [b"\0" * 120, b"\xf8\x5a\x8c\x6a\xde\xf5\xd9\x7e\xec\xe9\x0c\xe3\x75\x8f\x29\x0b"]
    return b"".join(chunks)

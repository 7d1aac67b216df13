"""The glTF reader on mutated files: a clip or a MotionError, never another exception, a
hang or a huge allocation; what the writer makes of a clip read from one reads back."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from motion import gltf
from motion.errors import MotionError
from tests.gltf_files import embedded_gltf_bytes, glb_bytes, rig_gltf
from tests.robustness.fuzzing import fuzz_settings
from tests.robustness.test_fuzz_parsers import assert_valid_motion, parse_or_refuse


def seed_document() -> dict:
    times = np.arange(6) / 30
    angles = np.radians(np.linspace(0, 40, 6))
    tracks = {
        ("hips", "translation"): (times, np.stack([0 * times, 1 + 0 * times, times], 1), "LINEAR"),
        ("head", "rotation"): (
            times, np.stack([np.sin(angles / 2), 0 * times, 0 * times, np.cos(angles / 2)], 1), "STEP"
        ),
    }  # fmt: skip
    return json.loads(embedded_gltf_bytes(rig_gltf(tracks)))


SEED = seed_document()
SEED_GLB = glb_bytes(
    rig_gltf({("hips", "translation"): ([0.0, 0.5], [[0, 1, 0], [0, 1, 1]], "LINEAR")})
)
ODD_VALUES = [None, -1, 0, 1, 2, 7, 2**31, 1e308, -0.5, "x", "", [], {}, [0, 0, 0, 0], True]


@st.composite
def mutated_json(draw) -> bytes:
    doc = json.loads(json.dumps(SEED))
    for _ in range(draw(st.integers(1, 3))):
        path = []
        node = doc
        while isinstance(node, dict | list) and node and draw(st.booleans()):
            key = draw(
                st.sampled_from(sorted(node) if isinstance(node, dict) else range(len(node)))
            )
            path.append((node, key))
            node = node[key]
        if not path:
            continue
        parent, key = path[-1]
        parent[key] = copy.deepcopy(draw(st.sampled_from(ODD_VALUES)))  # never shared
    return json.dumps(doc).encode()


@fuzz_settings(200)
@given(data=mutated_json())
def test_gltf_mutated_documents(data: bytes) -> None:
    motion = parse_or_refuse(gltf.loads, data, max_frames=5000)
    if motion is not None:
        assert_valid_motion(motion)


@fuzz_settings(200)
@given(flips=st.lists(st.tuples(st.integers(0, len(SEED_GLB) - 1), st.integers(0, 7)), max_size=4),
       cut=st.integers(0, len(SEED_GLB)))  # fmt: skip
def test_gltf_mutated_binary(flips, cut) -> None:
    data = bytearray(SEED_GLB)
    for i, bit in flips:
        data[i] ^= 1 << bit
    motion = parse_or_refuse(gltf.loads, bytes(data[:cut]), max_frames=5000)
    if motion is not None:
        assert_valid_motion(motion)


def test_a_node_placed_absurdly_far_is_refused_as_in_bvh() -> None:
    """A node translation of 2**31 (one of ODD_VALUES; the fuzzer found it on a fresh clone)
    read as a clip the BVH reader would refuse to read back: refused with the same bound."""
    doc = json.loads(json.dumps(SEED))
    doc["nodes"][1]["translation"] = [2**31, 1.0, 0.0]
    with pytest.raises(MotionError, match="absurdly large"):
        gltf.loads(json.dumps(doc).encode())
    doc["nodes"][1]["translation"] = [1e6, 1.0, 0.0]  # far, but a position: read and written
    assert_valid_motion(gltf.loads(json.dumps(doc).encode()))

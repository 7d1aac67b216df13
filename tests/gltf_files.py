"""glTF files made by code for tests: a small skinned rig built with pygltflib, and the
Blender-exported GLBs of real BVH clips (:func:`blender_glbs`, skipped without Blender)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
GLB_TOOL = REPO / "tests" / "blender" / "glb_tool.py"
BLENDER = shutil.which("blender")


def blender_run(*args: str, timeout: float = 120) -> None:
    """Run ``tests/blender/glb_tool.py`` in headless Blender; skip the test without Blender."""
    if BLENDER is None:
        pytest.skip("Blender is not installed (apt-get install blender python3-numpy)")
    cmd = [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1"]
    cmd += ["--python", str(GLB_TOOL), "--", *args]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        raise AssertionError(f"Blender failed ({result.returncode}):\n{result.stdout[-3000:]}")


def pack(arrays: list[np.ndarray]) -> tuple[bytes, list[tuple[int, int]]]:
    """Float32 arrays back to back (4-byte aligned): the blob and each one's (offset, length)."""
    blob = b""
    spans = []
    for a in arrays:
        raw = np.ascontiguousarray(a, dtype="<f4").tobytes()
        spans.append((len(blob), len(raw)))
        blob += raw
    return blob, spans


def rig_gltf(
    tracks: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, str]] | None = None,
    *,
    armature_rotation=(0.0, 0.0, 0.0, 1.0),
    armature_scale=(1.0, 1.0, 1.0),
    skin: bool = True,
    extra_animation: bool = False,
):
    """A pygltflib ``GLTF2``: node "Armature" above joints hips -> spine -> head (the
    spine node rotated 90 degrees about X at rest), a one-triangle mesh "Body" skinned to
    them with material "Skin", and an animation "Take" with ``tracks`` ((joint, path) ->
    (times, values, interpolation)). ``extra_animation`` adds a second animation "Other".
    """
    import pygltflib as G

    names = ["hips", "spine", "head"]
    q90 = [np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)]
    nodes = [
        G.Node(name="Armature", children=[1, 4], rotation=list(armature_rotation),
               scale=list(armature_scale)),
        G.Node(name="hips", children=[2], translation=[0.0, 1.0, 0.0]),
        G.Node(name="spine", children=[3], translation=[0.0, 0.3, 0.0], rotation=q90),
        G.Node(name="head", translation=[0.0, 0.0, -0.4]),
        G.Node(name="Body", mesh=0, skin=0 if skin else None),
    ]  # fmt: skip
    arrays = [
        np.array([[0, 0, 0], [0, 1, 0], [0, 1.5, 0]], np.float32),  # positions
        np.tile(np.eye(4, dtype=np.float32).reshape(1, 16), (3, 1)),  # inverse binds
    ]
    channels, samplers = [], []
    all_tracks = dict(tracks or {})
    for (joint, path), (times, values, interpolation) in all_tracks.items():
        arrays += [np.asarray(times, np.float32)[:, None], np.asarray(values, np.float32)]
        samplers.append((len(arrays) - 2, len(arrays) - 1, interpolation))
        channels.append((names.index(joint) + 1, path))
    if extra_animation:
        arrays += [
            np.array([[0.0], [1.0]], np.float32),
            np.array([[0, 1, 0], [0, 2, 0]], np.float32),
        ]
    blob, spans = pack(arrays)
    views = [G.BufferView(buffer=0, byteOffset=o, byteLength=n) for o, n in spans]

    def accessor(k: int, kind: str) -> G.Accessor:
        a = arrays[k]
        return G.Accessor(
            bufferView=k, componentType=G.FLOAT, count=len(a), type=kind,
            min=[float(x) for x in a.min(axis=0)], max=[float(x) for x in a.max(axis=0)],
        )  # fmt: skip

    kinds = ["VEC3", "MAT4"]
    for k in range(2, len(arrays)):
        width = arrays[k].shape[1]
        kinds.append("SCALAR" if width == 1 else f"VEC{width}")
    accessors = [accessor(k, kind) for k, kind in enumerate(kinds)]
    animations = []
    if channels:
        animations.append(
            G.Animation(
                name="Take",
                samplers=[
                    G.AnimationSampler(input=i, output=o, interpolation=m) for i, o, m in samplers
                ],
                channels=[
                    G.AnimationChannel(sampler=k, target=G.AnimationChannelTarget(node=n, path=p))
                    for k, (n, p) in enumerate(channels)
                ],
            )
        )
    if extra_animation:
        n = len(arrays)
        animations.append(
            G.Animation(
                name="Other",
                samplers=[G.AnimationSampler(input=n - 2, output=n - 1)],
                channels=[G.AnimationChannel(sampler=0, target=G.AnimationChannelTarget(node=1, path="translation"))],
            )
        )  # fmt: skip
    gltf = G.GLTF2(
        asset=G.Asset(version="2.0"),
        scene=0,
        scenes=[G.Scene(nodes=[0])],
        nodes=nodes,
        meshes=[G.Mesh(name="Body", primitives=[G.Primitive(attributes=G.Attributes(POSITION=0), material=0)])],
        materials=[G.Material(name="Skin")],
        skins=[G.Skin(joints=[1, 2, 3], inverseBindMatrices=1)] if skin else [],
        animations=animations,
        accessors=accessors,
        bufferViews=views,
        buffers=[G.Buffer(byteLength=len(blob))],
    )  # fmt: skip
    gltf.set_binary_blob(blob)
    return gltf


def glb_bytes(gltf) -> bytes:
    return b"".join(gltf.save_to_bytes())


def embedded_gltf_bytes(gltf) -> bytes:
    """The same document as ``.gltf`` JSON with its buffer in a base64 data URI."""
    import copy
    import warnings

    from pygltflib import BufferFormat

    doc = copy.deepcopy(gltf)
    doc.set_binary_blob(gltf.binary_blob())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc.convert_buffers(BufferFormat.DATAURI)
    return doc.gltf_to_json().encode()

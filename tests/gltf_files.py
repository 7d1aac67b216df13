"""glTF files made by code for tests: a small skinned rig and a character of any BVH
skeleton built with pygltflib, Blender's GLB export of BVH clips (:func:`blender_run`,
skipped without Blender), and what three.js's GLTFLoader reads of a file
(:func:`three_js_summary`, skipped without node and npm)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
GLB_TOOL = REPO / "tests" / "blender" / "glb_tool.py"
BLENDER = shutil.which("blender")
THREE_VERSION = "0.170.0"  # the release vendored for the preview page (r170)
NODE_SCRIPT = REPO / "tests" / "node" / "gltf_summary.mjs"


def blender_run(*args: str, timeout: float = 120) -> None:
    """Run ``tests/blender/glb_tool.py`` in headless Blender; skip the test without Blender."""
    if BLENDER is None:
        pytest.skip("Blender is not installed (apt-get install blender python3-numpy)")
    cmd = [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1"]
    cmd += ["--python", str(GLB_TOOL), "--", *args]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        raise AssertionError(f"Blender failed ({result.returncode}):\n{result.stdout[-3000:]}")


def three_js_folder() -> Path:
    """A folder with npm ``three`` (installed once into the user's cache) and the script."""
    npm, node = shutil.which("npm"), shutil.which("node")
    if npm is None or node is None:
        pytest.skip("node and npm are not installed (apt-get install nodejs npm)")
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "motion-style"
    folder = cache / f"npm-three-{THREE_VERSION}"
    loader = folder / "node_modules" / "three" / "examples" / "jsm" / "loaders" / "GLTFLoader.js"
    if not loader.exists():
        folder.mkdir(parents=True, exist_ok=True)
        result = subprocess.run(
            [npm, "install", "--prefix", str(folder), "--no-audit", "--no-fund",
             "--loglevel=error", f"three@{THREE_VERSION}"],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        if result.returncode != 0 or not loader.exists():
            pytest.skip(f"npm could not install three@{THREE_VERSION}: {result.stderr[-300:]}")
    shutil.copy(NODE_SCRIPT, folder / NODE_SCRIPT.name)
    return folder


def three_js_summary(path: Path) -> dict:
    """What three.js's GLTFLoader reads of a glTF file (``tests/node/gltf_summary.mjs``):
    node names, skinned meshes, materials, each animation's name, duration, tracks, keys."""
    folder = three_js_folder()
    result = subprocess.run(
        ["node", str(folder / NODE_SCRIPT.name), str(path)],
        capture_output=True, text=True, timeout=60, cwd=folder,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def three_js_name(name: str) -> str:
    """three.js's PropertyBinding.sanitizeNodeName: no whitespace, none of []./:"""
    return re.sub(r"[\[\]\.:/]", "", re.sub(r"\s", "_", name))


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


def character_glb(motion, *, animated: bool = True) -> bytes:
    """A GLB of ``motion``'s skeleton as a skinned character, built with pygltflib: node
    "Character" above one node per joint (rest: the joint's offset, no rotation, so the
    file reads back as the motion less its End Sites), a point-cloud mesh "Body" (a vertex
    at each joint, weighted to it) with material "Skin", and (``animated``) the animation
    "Take": every joint's rotation, the root's translation, a key per frame."""
    import pygltflib as G

    sk = motion.skeleton
    count = sk.num_joints
    rest = np.array(sk.offsets, dtype=np.float64)
    for j, p in enumerate(sk.parents):
        if p >= 0:
            rest[j] += rest[p]
    inverse_binds = np.tile(np.eye(4, dtype=np.float32), (count, 1, 1))
    inverse_binds[:, 3, :3] = -rest  # column-major: the translation is the last column
    arrays = [
        rest.astype(np.float32),
        np.stack([np.arange(count), *[np.zeros(count)] * 3], 1).astype(np.uint16),
        np.tile(np.array([1, 0, 0, 0], np.float32), (count, 1)),
        inverse_binds.reshape(count, 16),
    ]
    kinds = ["VEC3", "VEC4", "VEC4", "MAT4"]
    components = [G.FLOAT, G.UNSIGNED_SHORT, G.FLOAT, G.FLOAT]
    samplers, channels = [], []
    if animated:
        arrays.append((np.arange(motion.num_frames) / motion.fps).astype(np.float32)[:, None])
        kinds.append("SCALAR")
        components.append(G.FLOAT)
        times = len(arrays) - 1
        for j in range(count):
            for path, values in (
                ("rotation", motion.lrot[:, j]),
                ("translation", motion.lpos[:, j]),
            ):
                if path == "translation" and j != 0:
                    continue
                arrays.append(values.astype(np.float32))
                kinds.append("VEC4" if path == "rotation" else "VEC3")
                components.append(G.FLOAT)
                samplers.append(G.AnimationSampler(input=times, output=len(arrays) - 1))
                channels.append(G.AnimationChannel(
                    sampler=len(samplers) - 1, target=G.AnimationChannelTarget(node=j + 1, path=path)
                ))  # fmt: skip
    blob = b""
    views, accessors = [], []
    for k, a in enumerate(arrays):
        raw = np.ascontiguousarray(a).tobytes()
        blob += b"\0" * (-len(blob) % 4)
        views.append(G.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(raw)))
        blob += raw
        accessors.append(G.Accessor(
            bufferView=k, componentType=components[k], count=len(a), type=kinds[k],
            min=[float(x) for x in a.min(axis=0)] if k != 1 else None,
            max=[float(x) for x in a.max(axis=0)] if k != 1 else None,
        ))  # fmt: skip
    children: dict[int, list[int]] = {}
    for j, p in enumerate(sk.parents):
        children.setdefault(int(p), []).append(j + 1)
    nodes = [G.Node(name="Character", children=[1, count + 1])]
    for j, name in enumerate(sk.names):
        nodes.append(G.Node(name=name, translation=[float(v) for v in sk.offsets[j]],
                            children=children.get(j) or None))  # fmt: skip
    nodes.append(G.Node(name="Body", mesh=0, skin=0))
    attributes = G.Attributes(POSITION=0, JOINTS_0=1, WEIGHTS_0=2)
    gltf = G.GLTF2(
        asset=G.Asset(version="2.0"),
        scene=0,
        scenes=[G.Scene(nodes=[0])],
        nodes=nodes,
        meshes=[G.Mesh(name="Body", primitives=[G.Primitive(attributes=attributes, material=0, mode=G.POINTS)])],
        materials=[G.Material(name="Skin")],
        skins=[G.Skin(joints=list(range(1, count + 1)), inverseBindMatrices=3)],
        animations=[G.Animation(name="Take", samplers=samplers, channels=channels)] if animated else [],
        accessors=accessors,
        bufferViews=views,
        buffers=[G.Buffer(byteLength=len(blob))],
    )  # fmt: skip
    gltf.set_binary_blob(blob)
    return glb_bytes(gltf)

"""FBX files made by Blender as a Python module (bpy, the ``fbx`` extra) for tests, and what
Blender's FBX importer reads of a file: ``tests/blender/fbx_tool.py`` run in a subprocess
(bpy is loaded once per call there, never into the test process). Skips without bpy."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
FBX_TOOL = REPO / "tests" / "blender" / "fbx_tool.py"
NO_BPY = (
    "Blender as a Python module (bpy 4.2, the fbx extra) is not installed: "
    "pip install -e '.[fbx]' (CPython 3.11)"
)


def require_bpy() -> None:
    if importlib.util.find_spec("bpy") is None:
        pytest.skip(NO_BPY)


def fbx_tool(*args: str, timeout: float = 300) -> None:
    """Run ``tests/blender/fbx_tool.py`` with bpy; skip the test without bpy."""
    require_bpy()
    result = subprocess.run(
        [sys.executable, str(FBX_TOOL), *args], capture_output=True, text=True, timeout=timeout
    )
    if result.returncode != 0:
        raise AssertionError(f"bpy failed ({result.returncode}):\n{result.stderr[-3000:]}")


def make_fbx_files(bvh_path: Path, folder: Path, segments: int = 4) -> dict[str, Path]:
    """``bare`` (Blender's armature from ``bvh_path``), ``character`` (it with a skinned,
    textured-less body of ``segments`` x ``segments`` vertices a bone and a material), both
    FBX as Blender 4.2 exports them, and ``character_glb`` (the character as GLB)."""
    fbx_tool("make", str(bvh_path), str(folder), str(segments))
    return {
        "bare": folder / "bare.fbx",
        "character": folder / "character.fbx",
        "character_glb": folder / "character.glb",
    }


def blender_reads(paths: list[Path], folder: Path) -> list[dict]:
    """What Blender's FBX importer reads of each file (``fbx_tool.py inspect``)."""
    out = folder / "inspected.json"
    fbx_tool("inspect", str(out), *map(str, paths))
    return json.loads(out.read_text())

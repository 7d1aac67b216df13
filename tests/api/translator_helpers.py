"""The shipped translator as the translator's API tests meet it, and requests to it."""

from __future__ import annotations

import io
import json
import zipfile

import pytest

from service.config import Settings
from tests.conftest import data_path


def shipped_translator() -> dict | None:
    models_dir = Settings().models_dir[0]
    if not (models_dir / "translator").exists():
        return None
    try:
        doc = json.loads((models_dir / "manifest.json").read_text())
    except (OSError, ValueError):
        return None
    return next((m for m in doc.get("models", []) if m.get("family") == "translator"), None)


ENTRY = shipped_translator()
STYLES = sorted(ENTRY["extra"]["styles"]) if ENTRY else []
needs_model = pytest.mark.skipif(ENTRY is None, reason="no translator shipped in models/translator")
UNMAPPABLE = (
    b"HIERARCHY\nROOT Pelvis\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition"
    b" Zrotation Xrotation Yrotation\n JOINT Tail\n {\n  OFFSET 0 -10 0\n  CHANNELS 3"
    b" Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -5 0\n  }\n }\n}\n"
    b"MOTION\nFrames: 2\nFrame Time: 0.0333333\n0 0 0 0 0 0 0 0 0\n0 0 0 0 0 0 0 0 0\n"
)


def bandai(name: str) -> bytes:
    return data_path("bandai", "dataset-1", f"{name}.bvh").read_bytes()


def video_zip(number: int) -> bytes:
    """The OpenPose JSON files of a real treadmill video (23.976 fps), zipped."""
    folder = data_path("keypoints", f"openpose-treadmill-{number}")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as archive:
        for path in sorted(folder.glob("*.json")):
            archive.write(path, path.name)
    return buf.getvalue()


def transfer(client, content: bytes, query: str = "", files=None, **fields):
    parts = {"content": ("content.bvh", content, "text/plain"), **(files or {})}
    return client.post("/v1/transfer" + query, files=parts, data=fields)

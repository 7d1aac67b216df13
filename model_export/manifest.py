"""Add or replace one model entry in ``models/manifest.json``, hashing its files.

Every family's export script calls :func:`put_entry` with the files it wrote (relative to the
models folder); the entry is validated against the service's schema
(``service.manifest.ModelEntry``) before the manifest is rewritten atomically, and other
entries are left as they are (another family's export may run at another time).
"""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path
from typing import Any

from service.manifest import MANIFEST_NAME, SCHEMA_VERSION, Manifest, ModelEntry, sha256_of

REPO = Path(__file__).resolve().parent.parent
MODELS_DIR = REPO / "models"


def graph_spec(
    file: str, opset: int, inputs: list[tuple[str, list]], outputs: list[tuple[str, list]]
) -> dict[str, Any]:
    """A ``graphs`` item: ``inputs``/``outputs`` as ``(name, shape)`` pairs, float32."""

    def tensors(items):
        return [{"name": n, "dtype": "float32", "shape": list(s)} for n, s in items]

    return {"file": file, "opset": opset, "inputs": tensors(inputs), "outputs": tensors(outputs)}


def put_entry(
    entry: dict[str, Any], models_dir: Path = MODELS_DIR, replace_prefix: str | None = None
) -> ModelEntry:
    """Hash ``entry["files"]`` (a list of paths, or of ``{"path"}`` dicts, relative to
    ``models_dir``), validate and write the entry into the manifest, replacing any entry
    of the same name (and, with ``replace_prefix``, every entry whose name starts with it).
    Returns the validated entry."""
    models_dir = Path(models_dir)
    model = validated_entry(entry, models_dir)
    path = models_dir / MANIFEST_NAME
    if path.exists():
        doc = json.loads(path.read_text())
    else:
        doc = {"schema_version": SCHEMA_VERSION, "models": []}
    models = [
        m
        for m in doc.get("models", [])
        if m.get("name") != model.name
        and not (replace_prefix and str(m.get("name", "")).startswith(replace_prefix))
    ]
    models.append(model.model_dump(mode="json"))
    _write(path, {"schema_version": SCHEMA_VERSION, "models": models})
    return model


def validated_entry(entry: dict[str, Any], models_dir: Path = MODELS_DIR) -> ModelEntry:
    """``entry`` with its files hashed (a list of paths, or of ``{"path"}`` dicts, relative
    to ``models_dir``), validated against the service's schema."""
    files = []
    for item in entry["files"]:
        path = item if isinstance(item, str) else item["path"]
        files.append({"path": path, "sha256": sha256_of(Path(models_dir) / path)})
    return ModelEntry.model_validate({**entry, "files": files})


def dated_version(name: str, models_dir: Path = MODELS_DIR) -> str:
    """Today's date and a count, one above the manifest's entry ``name`` when that entry
    was exported today too (``2026-11-25.2`` after ``2026-11-25.1``): a re-export is a
    new version, which registered styles and caches key on."""
    today = dt.date.today().isoformat()
    path = Path(models_dir) / MANIFEST_NAME
    models = json.loads(path.read_text()).get("models", []) if path.exists() else []
    old = next((str(m.get("version", "")) for m in models if m.get("name") == name), "")
    day, _, count = old.partition(".")
    return f"{today}.{int(count) + 1 if day == today and count.isdigit() else 1}"


def put_evaluation(
    name: str, version: str, key: str, figures: dict[str, Any], models_dir: Path = MODELS_DIR
) -> None:
    """Record held-out evaluation ``figures`` under ``metrics.evaluation[key]`` of the entry
    ``name``, which must still be at ``version`` (figures of another model would mislead).
    A new export replaces the entry, and with it these figures."""
    path = Path(models_dir) / MANIFEST_NAME
    doc = json.loads(path.read_text())
    entry = _entry_at(doc, name, version)
    entry.setdefault("metrics", {}).setdefault("evaluation", {})[key] = figures
    _write(path, doc)


def update_entry(
    name: str,
    version: str,
    extra: dict[str, Any] | None = None,
    metrics: dict[str, Any] | None = None,
    models_dir: Path = MODELS_DIR,
    new_version: str | None = None,
) -> None:
    """Set keys of ``extra`` and ``metrics`` in the entry ``name``, which must still be at
    ``version``: what an export measures of its model once the entry is written. A change
    to what the model outputs takes ``new_version`` (and drops the figures measured on the
    old one, ``metrics.evaluation``)."""
    path = Path(models_dir) / MANIFEST_NAME
    doc = json.loads(path.read_text())
    entry = _entry_at(doc, name, version)
    entry.setdefault("extra", {}).update(extra or {})
    entry.setdefault("metrics", {}).update(metrics or {})
    if new_version is not None:
        entry["version"] = new_version
        entry["metrics"].pop("evaluation", None)
    _write(path, doc)


def _entry_at(doc: dict[str, Any], name: str, version: str) -> dict[str, Any]:
    entry = next((m for m in doc.get("models", []) if m.get("name") == name), None)
    if entry is None or entry.get("version") != version:
        found = None if entry is None else entry.get("version")
        raise ValueError(f"manifest has {name!r} at version {found!r}, not {version!r}")
    return entry


def _write(path: Path, doc: dict[str, Any]) -> None:
    """Validate ``doc`` against the service's schema and replace ``path`` atomically."""
    Manifest.model_validate(doc)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1) + "\n")
    os.replace(tmp, path)


def remove_entries(prefix: str, models_dir: Path = MODELS_DIR) -> None:
    """Drop every entry whose name starts with ``prefix``."""
    path = Path(models_dir) / MANIFEST_NAME
    if not path.exists():
        return
    doc = json.loads(path.read_text())
    doc["models"] = [m for m in doc.get("models", []) if not m["name"].startswith(prefix)]
    _write(path, doc)

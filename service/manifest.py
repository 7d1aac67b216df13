"""``models/manifest.json``: what ships, its schema, and the sha256 check run at start-up.

Schema (version 1)::

    {"schema_version": 1,
     "models": [
       {"name": "translator-bandai",          # unique, [A-Za-z0-9._-]
        "family": "translator",               # translator | fast | dance
        "version": "2025-01-30.1",
        "files": [                            # everything the model needs, all hashed
          {"path": "translator/encoder.onnx", "sha256": "<64 hex>"},
          {"path": "translator/stats.npz", "sha256": "<64 hex>"}],
        "graphs": {                           # one onnxruntime session each
          "encoder": {"file": "translator/encoder.onnx", "opset": 17,
                      "inputs":  [{"name": "motion", "dtype": "float32",
                                   "shape": ["batch", "time", 132]}],
                      "outputs": [{"name": "code", "dtype": "float32",
                                   "shape": ["batch", 64]}]}},
        "training_data": ["Bandai-Namco-Research-Motiondataset (CC BY-NC 4.0)"],
        "licence": "research and evaluation only (CC BY-NC 4.0 data)",
        "trained_at": "2025-01-30",
        "metrics": {"style_accuracy": 0.91},
        "extra": {"style_codes": {"happy": [0.1, ...]}}}]}   # free-form, per family

Paths are relative to the models folder (no ``..``, no absolute paths); every graph's
``file`` must be listed in ``files``. Symbolic dims are strings, fixed dims integers.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path, PurePosixPath
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

MANIFEST_NAME = "manifest.json"
SCHEMA_VERSION = 1
FAMILIES = ("translator", "fast", "dance")
Family = Literal["translator", "fast", "dance"]


class ManifestError(ValueError):
    """The manifest is missing, not JSON, or does not follow the schema."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class FileEntry(_Strict):
    path: str
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")

    @field_validator("path")
    @classmethod
    def _relative(cls, path: str) -> str:
        parts = PurePosixPath(path).parts
        if not parts or path.startswith("/") or "\\" in path or ".." in parts:
            raise ValueError(f"file path must be relative to the models folder: {path!r}")
        return path


class TensorSpec(_Strict):
    name: str
    dtype: str = "float32"
    shape: list[int | str] = Field(description="fixed dims as integers, symbolic as names")


class GraphSpec(_Strict):
    file: str
    opset: int = Field(ge=1)
    inputs: list[TensorSpec] = []
    outputs: list[TensorSpec] = []


class ModelEntry(_Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9._-]{1,100}$")
    family: Family
    version: str
    files: list[FileEntry]
    graphs: dict[str, GraphSpec]
    training_data: list[str] = []
    licence: str
    trained_at: str | None = None
    metrics: dict[str, Any] = {}
    extra: dict[str, Any] = {}

    @model_validator(mode="after")
    def _graphs_are_listed(self) -> ModelEntry:
        paths = [f.path for f in self.files]
        if len(set(paths)) != len(paths):
            raise ValueError(f"model {self.name!r} lists a file twice")
        for graph, spec in self.graphs.items():
            if spec.file not in paths:
                raise ValueError(f"graph {graph!r} of {self.name!r}: {spec.file!r} not in files")
        return self

    def file_entry(self, path: str) -> FileEntry:
        return next(f for f in self.files if f.path == path)


class Manifest(_Strict):
    schema_version: Literal[1]
    models: list[ModelEntry] = []

    @model_validator(mode="after")
    def _unique_names(self) -> Manifest:
        names = [m.name for m in self.models]
        if len(set(names)) != len(names):
            raise ValueError("model names must be unique")
        return self


def library_of(entry: ModelEntry) -> str:
    """The library ``entry``'s model learned from: ``extra.library`` (``motion-style-train``
    writes it), else its name without the family's prefix (``translator-bandai``:
    ``bandai``). ``library:style`` names a style of this model in a request."""
    library = entry.extra.get("library")
    if isinstance(library, str) and library:
        return library
    prefix = f"{entry.family}-"
    return entry.name[len(prefix) :] if entry.name.startswith(prefix) else entry.name


def load_manifest(models_dir: Path) -> Manifest:
    """Read and validate ``models_dir/manifest.json``; :class:`ManifestError` says what is wrong."""
    path = Path(models_dir) / MANIFEST_NAME
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ManifestError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        data = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ManifestError(f"{path} is not valid JSON: {exc}") from None
    try:
        return Manifest.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in err['loc']) or '(root)'}: {err['msg']}"
            for err in exc.errors()
        )
        raise ManifestError(f"{path} does not follow the manifest schema: {problems}") from None


def sha256_of(path: Path, chunk: int = 1 << 20) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def verify_files(entry: ModelEntry, models_dir: Path) -> list[str]:
    """Problems with ``entry``'s files (missing, unreadable, sha256 mismatch); empty if none."""
    problems = []
    for file in entry.files:
        path = Path(models_dir) / file.path
        try:
            actual = sha256_of(path)
        except FileNotFoundError:
            problems.append(f"missing file {file.path}")
            continue
        except OSError as exc:
            problems.append(f"cannot read {file.path}: {exc.strerror or exc}")
            continue
        if actual != file.sha256:
            problems.append(
                f"sha256 mismatch for {file.path}: manifest {file.sha256}, file {actual}"
            )
    return problems

"""Shared fixtures. Real data is read from ``$MOTION_DATA_DIR`` (default ``../shared/data``
beside the checkout); tests that need it skip with a reason when it is absent."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DATA_DIR = Path(os.environ.get("MOTION_DATA_DIR", REPO.parent / "shared" / "data")).resolve()


def pytest_configure(config) -> None:
    """Registered styles go to a folder of this run (apps and servers read the variable),
    never to the folder a developer's service keeps."""
    os.environ["MOTION_STYLES_DIR"] = tempfile.mkdtemp(prefix="motion-styles-")


def pytest_unconfigure(config) -> None:
    shutil.rmtree(os.environ.get("MOTION_STYLES_DIR", ""), ignore_errors=True)


def data_path(*parts: str) -> Path:
    """Path under the shared data folder; skips the calling test when it is missing."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared data not available: {path} (set MOTION_DATA_DIR)")
    return path


@pytest.fixture(scope="session")
def data_dir() -> Path:
    if not DATA_DIR.exists():
        pytest.skip(f"shared data not available at {DATA_DIR} (set MOTION_DATA_DIR)")
    return DATA_DIR


@pytest.fixture
def one_torch_thread():
    """Tiny networks: more threads only contend (the suite may share the cores)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def recorded_evaluation(record, report: dict, tmp_path: Path) -> dict:
    """``record(report, models)`` run on a copy of the shipped models folder in ``tmp_path``;
    the ``metrics.evaluation`` it left in the report's model entry."""
    import shutil

    from service.config import Settings
    from service.manifest import load_manifest

    models = tmp_path / "models"
    shutil.copytree(Settings().models_dir[0], models)
    record(report, models)
    entry = next(m for m in load_manifest(models).models if m.name == report["model_name"])
    return entry.metrics["evaluation"]

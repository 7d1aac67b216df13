"""The one dependency rule of DESIGN.md: motion imports no torch and none of the other
packages; service imports neither torch nor training; bvhio is for the benchmark only."""

from __future__ import annotations

import ast
import subprocess
import sys

import pytest

from tests.conftest import REPO

FORBIDDEN = {
    "motion": {"torch", "training", "service", "model_export", "onnxruntime", "librosa", "bvhio"},
    "service": {"torch", "training", "model_export", "librosa", "bvhio"},
}


def imported_roots(path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_respects_the_dependency_rule(package):
    for path in sorted((REPO / package).rglob("*.py")):
        bad = imported_roots(path) & FORBIDDEN[package]
        assert not bad, f"{path.relative_to(REPO)} imports {sorted(bad)}"


def test_importing_motion_loads_no_torch():
    code = (
        "import sys, importlib, pkgutil, motion\n"
        "for m in pkgutil.iter_modules(motion.__path__):\n"
        "    importlib.import_module('motion.' + m.name)\n"
        "assert 'torch' not in sys.modules, 'torch imported'\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_dance_training_needs_only_what_a_lent_gpu_machine_has():
    """``training.dance`` and its schedule run on a lent machine from a carried file
    (``training.carry dance``), whose image has PyTorch, NumPy, SciPy, numba, tqdm and
    TensorBoard (and soundfile and soxr as carried wheels), not the serving packages, Blender
    or librosa: importing them loads none of those."""
    pytest.importorskip("torch")
    code = (
        "import sys\n"
        "import training.dance, training.dance_schedule\n"
        "extra = {'fastapi', 'uvicorn', 'multipart', 'pydantic_settings', 'pygltflib', 'bpy',\n"
        "         'librosa'} & set(sys.modules)\n"
        "assert not extra, sorted(extra)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


# The data plane and its engines; only service.main, problems, middleware, auth, deps and
# service/routes speak HTTP.
HTTP_FREE = (
    "service.errors",
    "service.requests",
    "service.clips",
    "service.limits",
    "service.registered_styles",
    "service.registry",
    "service.inference",
    "service.dataplane",
    "service.fbx",
)


def test_engines_and_the_data_plane_load_no_web_framework():
    code = (
        "import sys, importlib, pkgutil, service.engines\n"
        "for m in pkgutil.iter_modules(service.engines.__path__):\n"
        "    importlib.import_module('service.engines.' + m.name)\n"
        f"for m in {HTTP_FREE!r}:\n"
        "    importlib.import_module(m)\n"
        "loaded = sorted({'fastapi', 'starlette'} & set(sys.modules))\n"
        "assert not loaded, f'{loaded} imported'\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr

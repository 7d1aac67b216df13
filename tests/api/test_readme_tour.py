"""The README's tour, run as written against a real ``python -m service``.

The tour is what a newcomer types first; if a route, a field or the fixture it names
changes, this fails instead of the newcomer.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.server import REPO, ServerProcess

README = REPO / "README.md"


def tour_commands() -> str:
    """The shell blocks between "## A tour" and the next section."""
    text = README.read_text()
    tour = text.split("## A tour", 1)[1].split("\n## ", 1)[0]
    return "\n".join(re.findall(r"```sh\n(.*?)```", tour, re.S))


def test_the_readme_points_only_inside_the_repo():
    links = re.findall(r"\]\(([^)]+)\)", README.read_text())
    assert links, "the README links its docs"
    for link in links:
        assert (REPO / link).exists(), f"README links {link}, which is not in the repo"


def test_every_setting_is_documented_and_the_readme_names_only_real_ones():
    from service.config import Settings

    def variables(text: str) -> set[str]:
        return set(re.findall(r"MOTION_[A-Z_]*[A-Z]", text))

    real = {"MOTION_" + name.upper() for name in Settings.model_fields}
    documented = variables((REPO / "docs" / "operations.md").read_text())
    assert real <= documented, f"docs/operations.md misses {sorted(real - documented)}"
    table = variables(README.read_text().split("## Settings", 1)[1].split("\n## ", 1)[0])
    assert table and table <= real, f"the README's settings name {sorted(table - real)}"


@pytest.mark.skipif(shutil.which("curl") is None, reason="the tour uses curl")
def test_the_readme_tour_works_as_written(tmp_path):
    commands = tour_commands()
    assert "localhost:8000" in commands
    # The tour runs in a clone's root: give it the files it names, and nothing else.
    shutil.copy(README, tmp_path / "README.md")
    shutil.copytree(REPO / "tests" / "data", tmp_path / "tests" / "data")
    shutil.copytree(REPO / "tests" / "blender", tmp_path / "tests" / "blender")
    (tmp_path / ".venv").symlink_to(Path(sys.executable).parent.parent)  # the clone's venv
    env = {"MOTION_STYLES_DIR": str(tmp_path / "styles")}
    with ServerProcess(env=env, log_path=tmp_path / "server.log", start_timeout=180) as server:
        script = commands.replace("http://localhost:8000", server.url).replace(
            "localhost:8000", server.url
        )
        done = subprocess.run(
            ["bash", "-e", "-c", script],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr + server.log()
    out = done.stdout
    assert '{"status":"ok"}' in out
    assert '"status":"ready"' in out
    assert '"name":"our-walk"' in out  # registered
    assert "\n204\n" in out  # and deleted
    assert '"status":400' in out and "not a BVH file" in out  # the README is no BVH
    assert "unknown field 'root_motoin'" in out  # a misspelt field is named
    written = re.findall(r"-o (\S+\.bvh)", commands)
    assert len(written) >= 7
    for name in written:
        head = (tmp_path / name).read_text()[:9]
        assert head == "HIERARCHY", f"{name} is not a BVH: {head!r}"
    if importlib.util.find_spec("bpy") is not None:  # the FBX part ran (the fbx extra)
        assert (tmp_path / "proud.fbx").read_bytes().startswith(b"Kaydara FBX Binary")

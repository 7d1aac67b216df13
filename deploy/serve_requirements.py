"""Print the pinned requirements of the service image: the base dependencies and the
``serve`` extra of pyproject.toml (no torch, no training or test tools), one per line, and
those of any other extras named (the ``:fbx`` image adds ``fbx``).

    python deploy/serve_requirements.py > requirements.txt   # what the Dockerfile installs
    python deploy/serve_requirements.py pyproject.toml serve fbx
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path


def serve_requirements(pyproject: Path, extras: tuple[str, ...] = ("serve",)) -> list[str]:
    project = tomllib.loads(pyproject.read_text())["project"]
    optional = project["optional-dependencies"]
    unknown = sorted(set(extras) - set(optional))
    if unknown:
        raise SystemExit(f"no such extra in {pyproject}: {', '.join(unknown)}")
    return [*project["dependencies"], *(req for extra in extras for req in optional[extra])]


if __name__ == "__main__":
    path = (
        Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent.parent / "pyproject.toml"
    )
    print("\n".join(serve_requirements(path, tuple(sys.argv[2:]) or ("serve",))))

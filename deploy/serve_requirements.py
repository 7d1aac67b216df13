"""Print the pinned requirements of the service image: the base dependencies and the
``serve`` extra of pyproject.toml (no torch, no training or test tools), one per line.

    python deploy/serve_requirements.py > requirements.txt   # what the Dockerfile installs
"""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path


def serve_requirements(pyproject: Path) -> list[str]:
    project = tomllib.loads(pyproject.read_text())["project"]
    return [*project["dependencies"], *project["optional-dependencies"]["serve"]]


if __name__ == "__main__":
    path = (
        Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent.parent / "pyproject.toml"
    )
    print("\n".join(serve_requirements(path)))

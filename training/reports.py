"""How an evaluation hands over its report: a table for a person on stdout, and the JSON that
``python -m model_export.evaluations`` records in the manifest."""

from __future__ import annotations

import json
from pathlib import Path


def publish(report: dict, table: str, path: Path | None) -> None:
    """Print ``table`` (the report as markdown) and, given a ``path``, write ``report`` there
    as JSON, its folder made if missing."""
    print()
    print(table)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(report, indent=1))

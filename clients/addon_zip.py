"""``python -m clients.addon_zip OUT.zip``: the Blender add-on folder as a zip that
Blender installs (Edit > Preferences > Add-ons > Install...); ``make blender-addon``."""

from __future__ import annotations

import sys
import zipfile
from pathlib import Path

ADDON = Path(__file__).resolve().parent / "blender" / "motion_style"


def build(out: Path) -> Path:
    """Write the zip (``motion_style/*.py``, no caches) to ``out``; return ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for path in sorted(ADDON.glob("*.py")):
            z.write(path, Path(ADDON.name) / path.name)
    return out


if __name__ == "__main__":
    print(build(Path(sys.argv[1] if len(sys.argv) > 1 else "dist/motion_style.zip")))

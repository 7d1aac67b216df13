"""Style names: the two Bandai datasets name three styles differently, and those count as one.

Dataset-1's ``old``, ``tired`` and ``masculinity`` are dataset-2's ``elderly``,
``exhausted`` and ``masculine``; the merged vocabulary has 16 styles. Models trained
before the merge still ship all 19 names; :func:`canonical_style` gives the one name each
stands for, so evaluations score them against it and the service can list which is which.
"""

from __future__ import annotations

import numpy as np

STYLE_ALIASES: dict[str, str] = {"old": "elderly", "tired": "exhausted", "masculinity": "masculine"}


def canonical_style(name: str) -> str:
    """The merged name of style ``name`` (itself unless it is an alias)."""
    return STYLE_ALIASES.get(name, name)


def taken_from_normal(codes: np.ndarray, names: list[str], gain: float) -> np.ndarray:
    """Style ``codes (S, D)`` of ``names`` taken ``gain`` times as far from "normal"'s, on
    the line through it (float32): the codes the translator's names play. Unchanged where
    no style is called "normal"."""
    codes = np.asarray(codes, dtype=np.float32)
    if "normal" not in names or gain == 1.0:
        return codes.copy()
    normal = codes[names.index("normal")]
    return (normal + np.float32(gain) * (codes - normal)).astype(np.float32)

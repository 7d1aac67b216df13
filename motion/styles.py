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


def exaggerated(
    codes: np.ndarray, gains: np.ndarray, centre: np.ndarray | None = None
) -> np.ndarray:
    """Style ``codes (S, D)`` each taken its ``gains (S,)`` times as far from ``centre``
    (default their mean), on the line through it (float32): the codes the translator's
    names and style clips play. A mean of a style's takes' codes lies nearer the centre
    than its takes do, and an encoder's code of one clip nearer than the clip's style."""
    codes = np.asarray(codes, dtype=np.float32)
    centre = codes.mean(axis=0) if centre is None else np.asarray(centre, dtype=np.float32)
    gains = np.asarray(gains, dtype=np.float32)[:, None]
    return (centre + gains * (codes - centre)).astype(np.float32)

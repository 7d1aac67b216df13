"""Style names: the two Bandai datasets name three styles differently, and those count as one.

Dataset-1's ``old``, ``tired`` and ``masculinity`` are dataset-2's ``elderly``,
``exhausted`` and ``masculine``; the merged vocabulary has 16 styles. Models trained
before the merge still ship all 19 names; :func:`canonical_style` gives the one name each
stands for, so evaluations score them against it and the service can list which is which.
"""

from __future__ import annotations

STYLE_ALIASES: dict[str, str] = {"old": "elderly", "tired": "exhausted", "masculinity": "masculine"}


def canonical_style(name: str) -> str:
    """The merged name of style ``name`` (itself unless it is an alias)."""
    return STYLE_ALIASES.get(name, name)

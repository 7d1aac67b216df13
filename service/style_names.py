"""Style names in requests, when several models are served: ``style`` or ``library:style``.

Every field that takes a style name (``style_name`` of transfer, style-code and stylize, the
keys of ``style_mix``) takes ``library:style`` too: the style of the model of that family
trained on that library (:func:`service.manifest.library_of`, ``bandai`` for the
shipped models; the model's full name, ``translator-bandai``, works as well). The endpoint
picks the family, so ``bandai:happy`` names the translator's style on ``/v1/transfer`` and
the fast network's on ``/v1/stylize``. A bare name works while one model of the family offers
it (:meth:`service.registry.ModelRegistry.resolve` says what happens otherwise). Style names
never hold ``:``, library names may: the last ``:`` separates them. A style's name is
matched whatever its case ("Angry" names ``angry``), where only one style so spelled exists.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from service.requests import StylizeRequest

SEPARATOR = ":"


def split(name: str) -> tuple[str | None, str]:
    """``(library, style)`` of ``library:style``; ``(None, name)`` for a bare name."""
    library, separator, style = name.rpartition(SEPARATOR)
    return (library, style) if separator else (None, name)


def qualified(library: str, style: str) -> str:
    return f"{library}{SEPARATOR}{style}"


def requested(request: Any) -> list[str]:
    """The style names ``request`` asks for, as given (none for a clip or a registration)."""
    if isinstance(request, StylizeRequest):
        return [request.style_name]
    style = getattr(request, "style", None)
    names = getattr(style, "names", None)
    return names() if callable(names) else []


def bare(request: Any, spelled: dict[str, str] | None = None) -> Any:
    """``request`` with every style name it asks for without its ``library:``, and spelled
    as ``spelled`` says (bare name as asked -> as the model spells it; weights of a mix that
    named one style twice, with and without its library or in two cases, added up)."""
    spelled = spelled or {}

    def plain(name: str) -> str:
        style = split(name)[1]
        return spelled.get(style, style)

    if isinstance(request, StylizeRequest):
        return dataclasses.replace(request, style_name=plain(request.style_name))
    style = request.style
    if style.name is not None:
        style = dataclasses.replace(style, name=plain(style.name))
    elif style.mix:
        mix: dict[str, float] = {}
        for name, weight in style.mix.items():
            key = plain(name)
            mix[key] = mix.get(key, 0.0) + weight
        style = dataclasses.replace(style, mix=mix)
    return dataclasses.replace(request, style=style)


def only(request: Any, style: str) -> Any:
    """``request`` asking for the one bare name ``style`` (for the 404 of an unknown one)."""
    if isinstance(request, StylizeRequest):
        return dataclasses.replace(request, style_name=style)
    source = dataclasses.replace(request.style, kind="style_name", name=style, mix=None)
    return dataclasses.replace(request, style=source)

"""Engines, one per model family, and the registry that maps a family to its engine.

A family module (``service/engines/translator.py``) subclasses :class:`Engine` and calls
``register_engine("translator", TranslatorEngine)`` at import; add the module to
:data:`FAMILY_MODULES` so the app factory imports it. A manifest entry whose family has no
registered engine gets a :class:`GenericEngine`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from service.engines.base import Engine, GenericEngine, create_session
from service.manifest import FAMILIES

__all__ = [
    "ENGINE_FACTORIES",
    "FAMILY_MODULES",
    "Engine",
    "EngineFactory",
    "GenericEngine",
    "create_session",
    "import_family_engines",
    "register_engine",
]

# factory(entry, models_dir, settings, styles=the registered styles or None)
EngineFactory = Callable[..., Engine]

ENGINE_FACTORIES: dict[str, EngineFactory] = {}

# Modules that register a family's engine when imported, e.g. "service.engines.translator".
FAMILY_MODULES: tuple[str, ...] = (
    "service.engines.fast",
    "service.engines.dance",
    "service.engines.translator",
)


def register_engine(family: str, factory: EngineFactory) -> None:
    """Make ``factory(entry, models_dir, settings)`` build the engines of ``family``."""
    if family not in FAMILIES:
        raise ValueError(f"unknown model family {family!r}; families are {FAMILIES}")
    ENGINE_FACTORIES[family] = factory


def import_family_engines() -> None:
    """Import every module of :data:`FAMILY_MODULES` (they register themselves)."""
    for module in FAMILY_MODULES:
        importlib.import_module(module)

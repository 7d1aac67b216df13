"""``GET /v1/models``: every model folder's manifest, each model's library, licence and load
status, and the licence note."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter
from pydantic import BaseModel

from service.deps import RegistryDep
from service.errors import NotReady
from service.manifest import SCHEMA_VERSION, ModelEntry, library_of
from service.problems import problem_responses

router = APIRouter(tags=["models"])

LICENCE_NOTE = (
    "Each model states its licence and training data. The shipped models (libraries bandai "
    "and dwm) are trained on data under CC BY-NC 4.0 (Bandai Namco motion), research-only "
    "terms, or no licence for reuse (music): they are provided for research and evaluation "
    "only, not for commercial use. A studio's models (motion-style-train) carry the licence "
    "the studio declared for its library."
)


class ModelInfo(ModelEntry):
    library: str  # what ``library:style`` names (service.style_names)
    status: Literal["pending", "loading", "ready", "failed"]
    loaded: bool
    error: str | None = None
    warnings: list[str] = []  # loaded, but not quite as shipped (e.g. a float fallback)


class ModelsResponse(BaseModel):
    schema_version: int
    state: Literal["idle", "loading", "ready", "failed"]
    licence_note: str
    models: list[ModelInfo]


@router.get(
    "/v1/models",
    summary="The model manifest with load status and licence",
    responses=problem_responses(503),
)
async def list_models(registry: RegistryDep) -> ModelsResponse:
    if len(registry.manifests) < len(registry.models_dirs):
        if registry.state == "failed":
            raise NotReady("; ".join(registry.reasons()), state=registry.state)
        raise NotReady("the manifest is being read", headers={"Retry-After": "1"})
    models = []
    for entry in registry.entries:
        status = registry.model_status(entry.name)
        engine = registry.engines.get(entry.name)
        models.append(
            ModelInfo(
                **entry.model_dump(),
                library=library_of(entry),
                status=status,
                loaded=status == "ready",
                error=registry.errors.get(entry.name),
                warnings=engine.warnings if engine is not None else [],
            )
        )
    return ModelsResponse(
        schema_version=SCHEMA_VERSION,
        state=registry.state,
        licence_note=LICENCE_NOTE,
        models=models,
    )

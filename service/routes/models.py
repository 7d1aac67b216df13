"""``GET /v1/models``: the manifest, each model's load status, and the licence note."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter
from pydantic import BaseModel

from service.deps import RegistryDep
from service.errors import NotReady
from service.manifest import ModelEntry
from service.problems import problem_responses

router = APIRouter(tags=["models"])

LICENCE_NOTE = (
    "The shipped models are trained on data under CC BY-NC 4.0 (Bandai Namco motion), "
    "research-only terms, or no licence for reuse (music). They are provided for research "
    "and evaluation only, not for commercial use; see each model's training_data and licence."
)


class ModelInfo(ModelEntry):
    status: Literal["pending", "loading", "ready", "failed"]
    loaded: bool
    error: str | None = None


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
    manifest = registry.manifest
    if manifest is None:
        if registry.state == "failed":
            raise NotReady("; ".join(registry.reasons()), state=registry.state)
        raise NotReady("the manifest is being read", headers={"Retry-After": "1"})
    models = []
    for entry in manifest.models:
        status = registry.model_status(entry.name)
        models.append(
            ModelInfo(
                **entry.model_dump(),
                status=status,
                loaded=status == "ready",
                error=registry.errors.get(entry.name),
            )
        )
    return ModelsResponse(
        schema_version=manifest.schema_version,
        state=registry.state,
        licence_note=LICENCE_NOTE,
        models=models,
    )

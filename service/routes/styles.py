"""``GET /v1/styles``: the styles each family offers, collected from the ready engines."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict

from service.deps import RegistryDep

router = APIRouter(tags=["styles"])


class StyleInfo(BaseModel):
    model_config = ConfigDict(extra="allow")

    name: str
    model: str
    clips: int | None = None


class StylesResponse(BaseModel):
    translator: list[StyleInfo]
    fast: list[StyleInfo]
    dance: list[StyleInfo]


@router.get("/v1/styles", summary="Style names per model family", response_model_exclude_none=True)
async def list_styles(registry: RegistryDep) -> StylesResponse:
    return StylesResponse.model_validate(registry.styles())

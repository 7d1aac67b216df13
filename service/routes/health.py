"""Liveness and readiness, plus the Open Inference Protocol (KServe v2) aliases."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter
from pydantic import BaseModel

from service.deps import RegistryDep
from service.errors import NotReady
from service.problems import problem_responses

router = APIRouter(tags=["health"])


class Liveness(BaseModel):
    status: Literal["ok"] = "ok"


class Readiness(BaseModel):
    status: Literal["ready"] = "ready"
    models: list[dict[str, Any]]


class LiveV2(BaseModel):
    live: bool


class ReadyV2(BaseModel):
    ready: bool


@router.get("/healthz", summary="Liveness: 200 while the process runs")
async def get_healthz() -> Liveness:
    return Liveness()


@router.get(
    "/readyz",
    summary="Readiness: 200 when every model is loaded and warmed",
    responses=problem_responses(503),
)
async def get_readyz(registry: RegistryDep) -> Readiness:
    registry.require_ready()
    return Readiness(models=registry.readiness()["models"])


@router.get("/v2/health/live", summary="Liveness (Open Inference Protocol)")
async def get_live_v2() -> LiveV2:
    return LiveV2(live=True)


@router.get(
    "/v2/health/ready",
    summary="Readiness (Open Inference Protocol)",
    responses=problem_responses(503),
)
async def get_ready_v2(registry: RegistryDep) -> ReadyV2:
    if not registry.ready:
        info = registry.readiness()
        raise NotReady("; ".join(info["reasons"]), ready=False, **info)
    return ReadyV2(ready=True)

"""Liveness and readiness, plus the Open Inference Protocol (KServe v2) aliases."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Request
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


def _require_blender(request: Request) -> None:
    """503 while the FBX pool's Blender workers start (after the models, before readiness)."""
    warm = request.app.state.blender_warm
    if warm is not None and not warm.is_set():
        reason = "Blender workers (FBX) are starting"
        raise NotReady(reason, headers={"Retry-After": "2"}, state="loading", reasons=[reason])


@router.get(
    "/readyz",
    summary="Readiness: 200 when every model is loaded and warmed (and Blender, for FBX)",
    responses=problem_responses(503),
)
async def get_readyz(registry: RegistryDep, request: Request) -> Readiness:
    registry.require_ready()
    _require_blender(request)
    return Readiness(models=registry.readiness()["models"])


@router.get("/v2/health/live", summary="Liveness (Open Inference Protocol)")
async def get_live_v2() -> LiveV2:
    return LiveV2(live=True)


@router.get(
    "/v2/health/ready",
    summary="Readiness (Open Inference Protocol)",
    responses=problem_responses(503),
)
async def get_ready_v2(registry: RegistryDep, request: Request) -> ReadyV2:
    if not registry.ready:
        info = registry.readiness()
        raise NotReady("; ".join(info["reasons"]), ready=False, **info)
    _require_blender(request)
    return ReadyV2(ready=True)

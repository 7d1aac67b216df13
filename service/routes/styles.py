"""``GET /v1/styles``: the styles each family offers, collected from the ready engines;
``POST /v1/styles`` and ``DELETE /v1/styles/{name}``: translator styles registered from a
studio's own clips (:mod:`service.registered_styles`), listed among the translator's with
``"registered": true`` and used by ``style_name`` and ``style_mix`` like the shipped ones."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Path, Request, UploadFile
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict

from service import pipeline
from service.deps import InferenceDep, RegistryDep, SettingsDep, StylesDep
from service.engines import Engine
from service.engines.translator import StyleCodeRequest, StyleSource
from service.errors import Conflict, NotFound, problem_responses
from service.registered_styles import (
    NAME_RULE,
    RegisterStyleRequest,
    StyleStore,
    check_clip_count,
    check_name,
    register,
)
from service.registry import ModelRegistry

router = APIRouter(tags=["styles"])


class StyleInfo(BaseModel):
    model_config = ConfigDict(extra="allow")

    name: str
    model: str
    clips: int | None = None
    registered: bool | None = None  # translator styles: registered from a studio's clips


class StylesResponse(BaseModel):
    translator: list[StyleInfo]
    fast: list[StyleInfo]
    dance: list[StyleInfo]


class NearStyle(BaseModel):
    style: str
    distance: float


class RegisteredStyleInfo(BaseModel):
    name: str
    registered: bool
    code: list[float]
    nearest: list[NearStyle]
    clips: int
    frames: int
    velocity_factor: float
    speed: float
    spread: float
    model: dict[str, str]
    created: str
    warnings: list[str]
    timings_ms: dict[str, float]


@router.get("/v1/styles", summary="Style names per model family", response_model_exclude_none=True)
async def list_styles(registry: RegistryDep) -> StylesResponse:
    styles = registry.styles()
    for style in styles.get("translator", []):
        style.setdefault("registered", False)
    return StylesResponse.model_validate(styles)


def translator_engine(registry: ModelRegistry) -> Engine:
    """The first ready translator: 503 while the models load, 404 when none is installed."""
    engines = registry.by_family("translator")
    if engines:
        return engines[0]
    registry.require_ready()
    raise NotFound("no translator model is installed", models=sorted(registry.engines))


def shipped_family(name: str, registry: ModelRegistry, store: StyleStore) -> str | None:
    """The family that ships a style (or a translator alias) named ``name``, or None."""
    if name in store:
        return None
    for family, styles in registry.styles().items():
        if any(s["name"] == name and not s.get("registered") for s in styles):
            return family
    probe = StyleCodeRequest(StyleSource("style_name", name=name))
    if any(engine.accepts(probe) for engine in registry.by_family("translator")):
        return "translator"  # another name of a shipped style
    return None


@router.post(
    "/v1/styles",
    summary="Register a translator style from your own clips (BVH or GLB)",
    status_code=201,
    response_model=RegisteredStyleInfo,
    responses=problem_responses(400, 404, 409, 413, 415, 422, 503, 504, 507),
)
async def register_style(
    request: Request,
    settings: SettingsDep,
    registry: RegistryDep,
    runner: InferenceDep,
    store: StylesDep,
    name: Annotated[str, Form(min_length=1, max_length=100, description=NAME_RULE)],
    clips: Annotated[
        list[UploadFile], File(description="clips in the style (BVH or glTF), any humanoid rig")
    ],
    mapping: Annotated[str | None, Form(description="JSON joint-name map (the clips)")] = None,
    speed: Annotated[
        float,
        Form(
            ge=0.5,
            le=2.0,
            description="time warp of a transfer to this style, against the content's own "
            "timing (1: keep it)",
        ),
    ] = 1.0,
) -> JSONResponse:
    name = check_name(name.strip())
    family = shipped_family(name, registry, store)
    if family is not None:
        raise Conflict(f"{name!r} is a shipped {family} style: choose another name", style=name)
    store.check_room(name)
    check_clip_count(len(clips), settings)
    job = RegisterStyleRequest(
        name=name,
        clips=[pipeline.upload(clip, settings, field="clips") for clip in clips],
        mapping=pipeline.parse_mapping(mapping),
        speed=speed,
    )
    engine = translator_engine(registry)
    done = await runner.run(register, engine, job, store, settings)
    style = done.style
    body: dict[str, Any] = {
        **style.to_json(),
        "registered": True,
        "nearest": done.nearest,
        "warnings": done.warnings,
        "timings_ms": {k: round(v, 2) for k, v in done.timer.ms.items()},
    }
    body.pop("sources")
    headers = {"Server-Timing": done.timer.server_timing()}
    return JSONResponse(body, status_code=201, headers=headers)


@router.delete(
    "/v1/styles/{name}",
    summary="Delete a registered style (shipped styles stay)",
    status_code=204,
    response_class=Response,
    responses=problem_responses(404, 409, 503, 507),
)
async def delete_style(
    registry: RegistryDep,
    store: StylesDep,
    name: Annotated[str, Path(max_length=200)],
) -> Response:
    if store.remove(name):
        return Response(status_code=204)
    if not registry.ready:
        registry.require_ready()  # which names are shipped is known once the models are
    family = shipped_family(name, registry, store)
    if family is not None:
        raise Conflict(f"{name!r} is a shipped {family} style and cannot be deleted", style=name)
    raise NotFound(f"no registered style named {name!r}", registered=[s.name for s in store.all()])

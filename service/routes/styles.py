"""``GET /v1/styles``: the styles each family offers, collected from the ready engines;
``POST /v1/styles`` and ``DELETE /v1/styles/{name}``: translator styles registered from a
studio's own clips (:mod:`service.registered_styles`), listed among the translator's with
``"registered": true`` and used by ``style_name`` and ``style_mix`` like the shipped ones."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, File, Form, Path, Request, UploadFile
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict

from service import auth
from service.config import Settings
from service.deps import DataPlaneDep, RegistryDep, SettingsDep
from service.errors import InvalidRequest, PayloadTooLarge
from service.problems import problem_responses
from service.registered_styles import NAME_RULE, check_name
from service.requests import RegisterStyleRequest, Registration
from service.routes import answers
from service.routes.fields import MappingField, parse_mapping, upload
from service.routes.known_fields import only_known_fields

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
    registered_by: str | None = None  # the name of the API key that registered it
    warnings: list[str]
    timings_ms: dict[str, float]


@router.get("/v1/styles", summary="Style names per model family", response_model_exclude_none=True)
async def list_styles(registry: RegistryDep) -> StylesResponse:
    styles = registry.styles()
    for style in styles.get("translator", []):
        style.setdefault("registered", False)
    return StylesResponse.model_validate(styles)


def check_clip_count(count: int, settings: Settings) -> None:
    """400 for no clip, 413 over ``max_style_clips``."""
    if count == 0:
        raise InvalidRequest("give one or more 'clips' to register a style from", field="clips")
    if count > settings.max_style_clips:
        raise PayloadTooLarge(
            f"{count} clips, over the limit of {settings.max_style_clips} (max_style_clips)",
            limit=settings.max_style_clips,
            limit_name="max_style_clips",
        )


@router.post(
    "/v1/styles",
    dependencies=[Depends(only_known_fields)],
    summary="Register a translator style from your own clips (BVH or GLB)",
    status_code=201,
    response_model=RegisteredStyleInfo,
    responses=problem_responses(400, 404, 409, 413, 415, 422, 503, 504, 507),
    openapi_extra=auth.requires("manage"),
)
async def register_style(
    request: Request,
    settings: SettingsDep,
    plane: DataPlaneDep,
    name: Annotated[str, Form(min_length=1, max_length=100, description=NAME_RULE)],
    clips: Annotated[
        list[UploadFile], File(description="clips in the style (BVH or glTF), any humanoid rig")
    ],
    mapping: MappingField = None,
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
    plane.check_new_style(name)
    check_clip_count(len(clips), settings)
    job = RegisterStyleRequest(
        name=name,
        clips=[upload(clip, settings, field="clips") for clip in clips],
        mapping=parse_mapping(mapping),
        speed=speed,
        registered_by=auth.key_name(request.scope),
    )
    done: Registration = await plane.infer("translator", job)
    body: dict[str, Any] = {
        **done.style.to_json(),
        "registered": True,
        "nearest": done.nearest,
        "warnings": done.warnings,
        "timings_ms": answers.timings_ms(done),
    }
    body.pop("sources")
    headers = {
        "Server-Timing": done.timer.server_timing(),
        **answers.warning_headers(done.warnings),
    }
    return JSONResponse(body, status_code=201, headers=headers)


@router.delete(
    "/v1/styles/{name}",
    summary="Delete a registered style (shipped styles stay)",
    status_code=204,
    response_class=Response,
    responses=problem_responses(404, 409, 503, 507),
    openapi_extra=auth.requires("manage"),
)
async def delete_style(
    plane: DataPlaneDep,
    name: Annotated[str, Path(max_length=200)],
) -> Response:
    plane.delete_style(name)
    return Response(status_code=204)

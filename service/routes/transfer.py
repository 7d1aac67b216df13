"""``POST /v1/transfer`` and ``POST /v1/style-code``: the translator (aberman2020).

A style comes from exactly one of: ``style`` (a BVH clip on any humanoid skeleton, mapped
like the content, with its own optional ``style_mapping``), ``keypoints`` (a video's 2D
keypoints: an OpenPose zip or JSON at ``keypoints_fps`` frames per second, default the
JSON document's rate, else 30),
``style_name`` (a style of the model's table, ``GET /v1/styles``) or ``style_mix`` (a JSON
object style name -> weight). None or several: a 400 problem naming the fields.

The result is a BVH on the content's skeleton and frame rate. With ``time_warp`` (default)
the motion is played faster or slower: for a style clip by the ratio of the style's and the
content's velocity factors (paper section 3.4), for a named style or mix by the style's
``speed`` (how fast it moves against the other styles on the same content, ``GET
/v1/styles``); clamped to [0.5, 2], none for keypoints. The frame count may change
(``X-Frames`` says it): the content clip as sent is warped by the same factor, so that its
joints without a canonical counterpart follow the new timing. Below full ``strength`` the
factor is raised to the power ``strength`` (0: no warp).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Depends, File, Form, Query, Request, UploadFile
from fastapi.responses import JSONResponse

from motion import features as Fe
from service import limits, pipeline
from service.config import Settings
from service.deps import RegistryDep, SettingsDep
from service.engines.translator import StyleCode, Transfer, TranslatorEngine, parse_mix
from service.errors import NotFound, problem_responses
from service.inference import run_inference
from service.metrics import StageTimer

router = APIRouter(tags=["transfer"])

STYLE_FIELDS = ("style", "keypoints", "style_name", "style_mix")
# Media types a keypoint upload may carry.
KEYPOINT_TYPES = (
    "application/zip",
    "application/x-zip-compressed",
    "application/json",
    "application/octet-stream",
    "text/",
)


def find_engine(registry) -> TranslatorEngine:
    """The ready translator engine: 503 while models load (or failed), 404 if none ships."""
    engines = [e for e in registry.by_family("translator") if isinstance(e, TranslatorEngine)]
    if engines:
        return engines[0]
    registry.require_ready()
    raise NotFound("no translator model is installed")


async def read_keypoints_upload(upload: UploadFile, settings: Settings) -> bytes:
    """The bytes of an uploaded keypoint file (zip or JSON); see ``pipeline.read_upload``."""
    return await pipeline.read_upload(
        upload,
        settings,
        field="keypoints",
        accept=KEYPOINT_TYPES,
        what="an OpenPose zip or JSON file",
    )


@dataclass
class StyleInput:
    """The one style input of a request, read on the event loop: ``kind`` (a field of
    :data:`STYLE_FIELDS`) and what it needs."""

    kind: str
    data: bytes | None = None
    name: str | None = None
    mix: dict[str, float] | None = None
    keypoints_fps: float | None = None  # None: the document's rate, else 30
    mapping: dict[str, str] | None = None


@dataclass
class StyleFields:
    """The style form fields /v1/transfer and /v1/style-code share (at most one is set)."""

    style: UploadFile | None
    keypoints: UploadFile | None
    style_name: str | None
    style_mix: str | None
    keypoints_fps: float | None
    style_mapping: str | None


def read_style_fields(
    style: Annotated[UploadFile, File(description=STYLE_DOC["style"])] = None,
    keypoints: Annotated[UploadFile, File(description=STYLE_DOC["keypoints"])] = None,
    style_name: Annotated[
        str | None, Form(max_length=100, description=STYLE_DOC["style_name"])
    ] = None,
    style_mix: Annotated[
        str | None, Form(max_length=10_000, description=STYLE_DOC["style_mix"])
    ] = None,
    keypoints_fps: Annotated[
        float, Form(gt=0, le=1000, description=STYLE_DOC["keypoints_fps"])
    ] = None,  # type: ignore[assignment]  (None: the document's rate, else 30)
    style_mapping: Annotated[str | None, Form(description=STYLE_DOC["style_mapping"])] = None,
) -> StyleFields:
    """The shared style fields as one dependency, so both routes declare them once."""
    return StyleFields(style, keypoints, style_name, style_mix, keypoints_fps, style_mapping)


async def read_style_input(
    engine: TranslatorEngine,
    settings: Settings,
    *,
    style: UploadFile | None,
    keypoints: UploadFile | None,
    style_name: str | None,
    style_mix: str | None,
    keypoints_fps: float | None,
    style_mapping: str | None,
) -> StyleInput:
    """Check that exactly one style input is given (400 naming the fields otherwise), check
    names (404) and mixes (400/404) at once, and read an uploaded file."""
    style_name = style_name.strip() if style_name and style_name.strip() else None
    style_mix = style_mix if style_mix and style_mix.strip() else None
    values = {"style": style, "keypoints": keypoints, "style_name": style_name,
              "style_mix": style_mix}  # fmt: skip
    given = [name for name, value in values.items() if value is not None]
    if len(given) != 1:
        which = "none" if not given else ", ".join(given)
        raise pipeline.InvalidField(
            f"give exactly one style input of {', '.join(STYLE_FIELDS)}; got {which}",
            fields=given,
            expected_one_of=list(STYLE_FIELDS),
        )
    kind = given[0]
    if kind == "style_name":
        engine.require_style(style_name)
        return StyleInput(kind, name=style_name)
    if kind == "style_mix":
        mix = parse_mix(style_mix)
        for name in mix:
            engine.require_style(name)
        return StyleInput(kind, mix=mix)
    if kind == "keypoints":
        data = await read_keypoints_upload(keypoints, settings)
        return StyleInput(kind, data=data, keypoints_fps=keypoints_fps)
    data = await pipeline.read_upload(style, settings, field="style")
    mapping = _parse_mapping(style_mapping, "style_mapping")
    return StyleInput(kind, data=data, mapping=mapping)


def _parse_mapping(text: str | None, field: str) -> dict[str, str] | None:
    """``pipeline.parse_mapping`` with the field's own name in its problems."""
    try:
        return pipeline.parse_mapping(text)
    except pipeline.InvalidField as exc:
        detail = exc.detail.replace("'mapping'", f"'{field}'")
        raise pipeline.InvalidField(detail, field=field) from None


def style_code(
    engine: TranslatorEngine, settings: Settings, style: StyleInput, timer: StageTimer
) -> StyleCode:
    """The style code of a request's style input (blocking: run it in the inference pool).
    A style clip's parse and retarget stages are timed as ``style_parse``/``style_retarget``."""
    if style.kind == "style_name":
        return engine.code_of_name(style.name)
    if style.kind == "style_mix":
        return engine.code_of_mix(style.mix)
    if style.kind == "keypoints":
        with timer.stage("style_parse"):
            kp = limits.read_keypoints(style.data, settings, fps=style.keypoints_fps)
        return engine.code_of_keypoints(kp, timer)
    inner = StageTimer(engine.name)
    try:
        clip = pipeline.load_clip(style.data, settings, inner, mapping=style.mapping, what="style")
    finally:
        for stage, ms in inner.ms.items():
            timer.ms[f"style_{stage}"] = timer.ms.get(f"style_{stage}", 0.0) + ms
    return engine.code_of_motion(clip.canonical, timer)


def finish_transfer(
    clip: pipeline.Clip, result: Transfer, settings: Settings, timer: StageTimer, warnings=()
) -> pipeline.Result:
    """The transfer back on the content's own skeleton and frame rate. With a time warp, the
    clip as sent is warped by the same factor first, so that the frame count follows the
    warp and joints without a canonical counterpart follow the new timing."""
    if result.warp != 1.0:
        with timer.stage("time_warp"):
            original = Fe.time_warp(clip.original, result.warp)
        limits.check_frames(original, settings, what="result")
        clip = dataclasses.replace(clip, original=original)
    return pipeline.finish(clip, result.motion, timer, warnings)


STYLE_DOC = {
    "style": "style clip (BVH, any humanoid skeleton)",
    "keypoints": "2D keypoints of a video (OpenPose zip of per-frame JSON files, or JSON)",
    "style_name": "a named style (GET /v1/styles)",
    "style_mix": 'JSON object style name -> weight, e.g. {"happy": 0.7, "old": 0.3}',
    "keypoints_fps": "frame rate of the keypoints (default: the JSON document's, else 30)",
    "style_mapping": "JSON joint-name map for the style clip",
}


@router.post(
    "/v1/transfer",
    summary="Re-style a BVH clip by an example clip, a video's keypoints, a name or a mix",
    response_class=pipeline.Response,
    responses=pipeline.bvh_responses("BVH on the content's skeleton and frame rate (or JSON)"),
)
async def transfer(
    request: Request,
    registry: RegistryDep,
    settings: SettingsDep,
    content: Annotated[UploadFile, File(description="content clip (BVH)")],
    style_fields: Annotated[StyleFields, Depends(read_style_fields)],
    strength: Annotated[float, Form(ge=0, le=1, description="0 keeps the content's style")] = 1.0,
    time_warp: Annotated[bool, Form(description="warp time by the velocity ratio")] = True,
    foot_cleanup: Annotated[bool, Form(description="pin the content's foot contacts")] = True,
    mapping: Annotated[str | None, Form(description="JSON joint-name map (content)")] = None,
    format: Annotated[pipeline.Format, Query()] = "bvh",  # noqa: A002
) -> pipeline.Response:
    engine = find_engine(registry)
    style_input = await read_style_input(engine, settings, **vars(style_fields))
    data = await pipeline.read_upload(content, settings)
    joint_map = pipeline.parse_mapping(mapping)

    def work() -> pipeline.Result:
        timer = StageTimer(engine.name)
        clip = pipeline.load_clip(data, settings, timer, mapping=joint_map)
        target = style_code(engine, settings, style_input, timer)
        result = engine.transfer(
            clip.canonical,
            target.code,
            strength=strength,
            time_warp=time_warp,
            foot_cleanup=foot_cleanup,
            style_velocity=target.velocity,
            style_speed=target.speed,
            timer=timer,
        )
        return finish_transfer(clip, result, settings, timer, target.warnings + result.warnings)

    result = await run_inference(request, work)
    return pipeline.respond(
        request,
        result,
        engine,
        fmt=format,
        upload_name=content.filename,
        suffix="transfer",
        endpoint="/v1/transfer",
    )


@router.post(
    "/v1/style-code",
    summary="The translator's style code of a style input, and the nearest named styles",
    responses=problem_responses(400, 404, 413, 415, 422, 503, 504),
)
async def style_code_of(
    request: Request,
    registry: RegistryDep,
    settings: SettingsDep,
    style_fields: Annotated[StyleFields, Depends(read_style_fields)],
) -> JSONResponse:
    engine = find_engine(registry)
    style_input = await read_style_input(engine, settings, **vars(style_fields))

    def work() -> tuple[StyleCode, StageTimer]:
        timer = StageTimer(engine.name)
        return style_code(engine, settings, style_input, timer), timer

    code, timer = await run_inference(request, work)
    body: dict[str, Any] = {
        "code": [round(float(v), 6) for v in code.code],
        "nearest": engine.nearest(code.code),
        "source": code.source,
        "velocity_factor": None if code.velocity is None else round(code.velocity, 4),
        "speed": None if code.speed is None else round(code.speed, 4),
        "model": {"name": engine.name, "version": engine.version},
        "timings_ms": {k: round(v, 2) for k, v in timer.ms.items()},
        "warnings": code.warnings,
    }
    headers = {
        "X-Model-Version": f"{engine.name}/{engine.version}",
        "Server-Timing": timer.server_timing(),
    }
    request_id = (request.scope.get("state") or {}).get("request_id", "")
    if request_id:
        headers["X-Request-Id"] = request_id
    return JSONResponse(body, headers=headers)

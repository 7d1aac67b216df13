"""``POST /v1/transfer`` and ``POST /v1/style-code``: the translator (aberman2020).

A style comes from exactly one of: ``style`` (a BVH or glTF clip on any humanoid skeleton, mapped
like the content, with its own optional ``style_mapping``), ``keypoints`` (a video's 2D
keypoints: an OpenPose zip or JSON at ``keypoints_fps`` frames per second, default the
JSON document's rate, else 30),
``style_name`` (a style of the model's table or a registered one, ``GET /v1/styles``) or ``style_mix`` (a JSON
object style name -> weight). None or several: a 400 problem naming the fields.

The result is on the content's skeleton and frame rate, in its format (BVH, or its GLB with the
new animation; ``?format=`` chooses). With ``time_warp`` (default)
the motion is played faster or slower: for a style clip by the ratio of the style's and the
content's velocity factors (paper section 3.4), for a named style or mix by the style's
``speed`` (how fast it moves against the other styles on the same content, ``GET
/v1/styles``); clamped to [0.5, 2], none for keypoints. The frame count may change
(``X-Frames`` says it): the content clip as sent is warped by the same factor, so that its
joints without a canonical counterpart follow the new timing. Below full ``strength`` the
factor is raised to the power ``strength`` (0: no warp).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Depends, File, Form, Request, Response, UploadFile
from fastapi.responses import JSONResponse

from service.config import Settings
from service.deps import DataPlaneDep, SettingsDep
from service.errors import InvalidRequest
from service.problems import problem_responses
from service.requests import StyleCodeRequest, StyleCodeResult, StyleSource, TransferRequest
from service.routes import answers
from service.routes.fields import ContentDep, parse_mapping, parse_mix, upload
from service.routes.known_fields import only_known_fields

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
STYLE_DOC = {
    "style": "style clip (BVH or glTF, any humanoid skeleton)",
    "keypoints": "2D keypoints of a video (OpenPose zip of per-frame JSON files, or JSON)",
    "style_name": "a named style (GET /v1/styles)",
    "style_mix": 'JSON object style name -> weight, e.g. {"happy": 0.7, "old": 0.3}',
    "keypoints_fps": "frame rate of the keypoints (default: the JSON document's, else 30)",
    "style_mapping": "JSON joint-name map for the style clip",
}


@dataclass
class StyleFields:
    """The style form fields /v1/transfer and /v1/style-code share (at most one is set)."""

    style: UploadFile | None
    keypoints: UploadFile | None
    style_name: str | None
    style_mix: str | None
    keypoints_fps: float | None
    style_mapping: str | None


async def read_style_fields(
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


def style_source(given: StyleFields, settings: Settings) -> StyleSource:
    """The one style input: exactly one of :data:`STYLE_FIELDS` (400 naming the fields
    otherwise), a mix parsed (400), an upload checked (415/413)."""
    name = given.style_name.strip() if given.style_name and given.style_name.strip() else None
    mix = given.style_mix if given.style_mix and given.style_mix.strip() else None
    values = {"style": given.style, "keypoints": given.keypoints, "style_name": name,
              "style_mix": mix}  # fmt: skip
    present = [field for field, value in values.items() if value is not None]
    if len(present) != 1:
        which = "none" if not present else ", ".join(present)
        raise InvalidRequest(
            f"give exactly one style input of {', '.join(STYLE_FIELDS)}; got {which}",
            fields=present,
            expected_one_of=list(STYLE_FIELDS),
        )
    kind = present[0]
    if kind == "style_name":
        return StyleSource(kind, name=name)
    if kind == "style_mix":
        return StyleSource(kind, mix=parse_mix(mix))
    if kind == "keypoints":
        clip = upload(
            given.keypoints,
            settings,
            field="keypoints",
            accept=KEYPOINT_TYPES,
            what="an OpenPose zip or JSON file",
        )
        return StyleSource(kind, upload=clip, keypoints_fps=given.keypoints_fps)
    clip = upload(given.style, settings, field="style")
    mapping = parse_mapping(given.style_mapping, "style_mapping")
    return StyleSource(kind, upload=clip, mapping=mapping)


@router.post(
    "/v1/transfer",
    dependencies=[Depends(only_known_fields)],
    summary="Re-style a clip (BVH or GLB) by an example clip, a video's keypoints, a name or a mix",
    response_class=Response,
    responses=answers.clip_responses("the content's format (or ?format=) on its skeleton and rate"),
)
async def transfer(
    request: Request,
    settings: SettingsDep,
    plane: DataPlaneDep,
    clip: ContentDep,
    style_fields: Annotated[StyleFields, Depends(read_style_fields)],
    strength: Annotated[
        float, Form(ge=0, le=1, description="0 gives the content back as sent")
    ] = 1.0,
) -> Response:
    job = TransferRequest(clip, style_source(style_fields, settings), strength)
    endpoint = answers.route_template(request)
    result = await plane.infer("translator", job, endpoint=endpoint)
    return answers.respond(result, upload_name=clip.filename)


@router.post(
    "/v1/style-code",
    dependencies=[Depends(only_known_fields)],
    summary="The translator's style code of a style input, and the nearest named styles",
    responses=problem_responses(400, 404, 413, 415, 422, 503, 504),
)
async def style_code_of(
    settings: SettingsDep,
    plane: DataPlaneDep,
    style_fields: Annotated[StyleFields, Depends(read_style_fields)],
) -> JSONResponse:
    job = StyleCodeRequest(style_source(style_fields, settings))
    result: StyleCodeResult = await plane.infer("translator", job)
    code, (name, version) = result.code, result.model
    body: dict[str, Any] = {
        "code": [round(float(v), 6) for v in code.code],
        "nearest": result.nearest,
        "source": code.source,
        "velocity_factor": None if code.velocity is None else round(code.velocity, 4),
        "speed": None if code.speed is None else round(code.speed, 4),
        "model": {"name": name, "version": version},
        "timings_ms": answers.timings_ms(result),
        "warnings": code.warnings,
    }
    headers = {**answers.timing_headers(result), **answers.warning_headers(code.warnings)}
    return JSONResponse(body, headers=headers)

"""``POST /v1/dance``: music in, a dance as long as the decoded audio out (BVH, or the GLB of
the ``skeleton`` sent with the dance as its animation)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, File, Form, Request, Response, UploadFile

from motion import dance_features as DF
from service.deps import DataPlaneDep, SettingsDep
from service.errors import InvalidRequest
from service.requests import DanceRequest
from service.routes import answers
from service.routes.fields import (
    FormatQuery,
    MappingField,
    RootMotionField,
    parse_mapping,
    text_upload,
    upload,
)
from service.routes.known_fields import only_known_fields

router = APIRouter(tags=["dance"])

AUDIO_TYPES = ("audio/", "application/octet-stream", "application/ogg", "video/ogg")
MAX_FPS = 240.0
ABSENT = ("", "null", "none", "auto")
"""Form values that mean "not given" (multipart has no null)."""


def check_genre(genre: str | None) -> str | None:
    """The genre's name, or None to predict it; 400 for an unknown name."""
    if genre is None or genre.strip().lower() in ABSENT:
        return None
    name = genre.strip().lower()
    if name not in DF.GENRES:
        raise InvalidRequest(f"unknown genre {genre!r}", field="genre", genres=list(DF.GENRES))
    return name


@router.post(
    "/v1/dance",
    dependencies=[Depends(only_known_fields)],
    summary="Generate a dance for a whole song (BVH as long as the decoded audio)",
    response_class=Response,
    responses=answers.clip_responses(
        "BVH on the canonical skeleton, or on `skeleton` when given (in its format)",
        dance=True,
    ),
)
async def create_dance(
    request: Request,
    settings: SettingsDep,
    plane: DataPlaneDep,
    audio: Annotated[UploadFile, File(description="music: wav, flac, ogg or mp3")],
    genre: Annotated[str | None, Form(description=f"one of {', '.join(DF.GENRES)}")] = None,
    seed: Annotated[int, Form(ge=0, le=2**31 - 1)] = 0,
    skeleton: Annotated[
        UploadFile | str | None,
        File(description="BVH (file or text) or glTF rig (animated or not) to retarget onto"),
    ] = None,
    fps: Annotated[float, Form(gt=0, le=MAX_FPS)] = 30.0,
    mapping: MappingField = None,
    format: FormatQuery = None,  # noqa: A002
    root_motion: RootMotionField = "keep",
) -> Response:
    rig = None
    if isinstance(skeleton, str):
        if skeleton.strip().lower() not in ABSENT:
            rig = text_upload(skeleton, settings, field="skeleton")
    elif skeleton is not None:
        rig = upload(skeleton, settings, field="skeleton")
    job = DanceRequest(
        audio=upload(
            audio, settings, field="audio", accept=AUDIO_TYPES, what="wav, flac, ogg or mp3"
        ),
        genre=check_genre(genre),
        seed=seed,
        skeleton=rig,
        fps=fps,
        mapping=parse_mapping(mapping),
        format=format,
        root_motion=root_motion,
    )
    result = await plane.infer("dance", job, endpoint=answers.route_template(request))
    return answers.respond(result, upload_name=audio.filename)

"""``POST /v1/dance``: music in, a dance as long as the decoded audio out (BVH)."""

from __future__ import annotations

import math
from typing import Annotated

from fastapi import APIRouter, File, Form, Query, Request, UploadFile

from motion import audio as A
from motion import bvh, retarget
from motion import dance_features as DF
from motion import kinematics as K
from service import limits, pipeline
from service.config import Settings
from service.deps import RegistryDep, SettingsDep
from service.engines.dance import DanceEngine
from service.errors import NotFound, PayloadTooLarge
from service.inference import run_inference
from service.metrics import StageTimer

router = APIRouter(tags=["dance"])

AUDIO_TYPES = ("audio/", "application/octet-stream", "application/ogg", "video/ogg")
MAX_FPS = 240.0


def find_engine(registry) -> DanceEngine:
    """The first ready dance engine; 503 while the models load, 404 when none is shipped."""
    for engine in registry.by_family("dance"):
        if isinstance(engine, DanceEngine):
            return engine
    if not registry.ready:
        registry.require_ready()
    raise NotFound("no dance model is loaded", models=sorted(registry.engines))


async def read_audio(upload: UploadFile, settings: Settings) -> bytes:
    """The bytes of the uploaded audio; see ``pipeline.read_upload``."""
    return await pipeline.read_upload(
        upload, settings, field="audio", accept=AUDIO_TYPES, what="wav, flac, ogg or mp3"
    )


ABSENT = ("", "null", "none", "auto")
"""Form values that mean "not given" (multipart has no null)."""


def check_genre(genre: str | None) -> str | None:
    """The genre's name, or None to predict it; 400 for an unknown name."""
    if genre is None or genre.strip().lower() in ABSENT:
        return None
    name = genre.strip().lower()
    if name not in DF.GENRES:
        raise pipeline.InvalidField(
            f"unknown genre {genre!r}", field="genre", genres=list(DF.GENRES)
        )
    return name


async def read_skeleton(skeleton: UploadFile | str | None, settings: Settings) -> bytes | None:
    """The optional ``skeleton``: an uploaded BVH file, BVH text sent as a plain field, or
    absent (no field, empty, or ``null``)."""
    if skeleton is None:
        return None
    if isinstance(skeleton, str):
        if skeleton.strip().lower() in ABSENT:
            return None
        data = skeleton.encode()
        if len(data) > settings.max_upload_bytes:
            raise PayloadTooLarge(
                f"'skeleton' is over {settings.max_upload_bytes} bytes",
                limit=settings.max_upload_bytes,
                limit_name="max_upload_bytes",
            )
        return data
    return await pipeline.read_upload(skeleton, settings, field="skeleton")


@router.post(
    "/v1/dance",
    summary="Generate a dance for a whole song (BVH as long as the decoded audio)",
    response_class=pipeline.Response,
    responses=pipeline.bvh_responses("BVH on the canonical skeleton, or on `skeleton` when given"),
)
async def create_dance(
    request: Request,
    registry: RegistryDep,
    settings: SettingsDep,
    audio: Annotated[UploadFile, File(description="music: wav, flac, ogg or mp3")],
    genre: Annotated[str | None, Form(description=f"one of {', '.join(DF.GENRES)}")] = None,
    seed: Annotated[int, Form(ge=0, le=2**31 - 1)] = 0,
    skeleton: Annotated[
        UploadFile | str | None, File(description="BVH (file or text) to retarget onto")
    ] = None,
    fps: Annotated[float, Form(gt=0, le=MAX_FPS)] = 30.0,
    mapping: Annotated[str | None, Form(description="JSON joint-name map")] = None,
    format: Annotated[pipeline.Format, Query()] = "bvh",  # noqa: A002
) -> pipeline.Response:
    engine = find_engine(registry)
    name = check_genre(genre)
    data = await read_audio(audio, settings)
    rig_data = await read_skeleton(skeleton, settings)
    joint_map = pipeline.parse_mapping(mapping)

    def work() -> pipeline.Result:
        timer = StageTimer(engine.name)
        with timer.stage("decode_audio"):
            samples, sr = limits.decode_audio(data, settings)
            A.check_not_silent(samples)
        seconds = len(samples) / sr
        frames = max(1, math.ceil(seconds * fps - 1e-9))
        limits.check_frames(frames, settings, what="result")
        limits.check_frames(math.ceil(seconds * DF.FPS), settings, what="result")
        clip = None
        if rig_data is not None:
            clip = pipeline.load_clip(rig_data, settings, timer, mapping=joint_map, what="skeleton")
        result = engine.dance(samples, sr, timer, genre=name, seed=seed)
        with timer.stage("resample"):
            canon = K.resample_count(result.motion, fps, frames)
        warnings = list(result.warnings)
        warnings.append(
            f"beat alignment {result.bas:.2f} (chance {result.bas_chance:.2f}) at "
            f"{result.tempo:.0f} bpm"
        )
        if clip is None:
            with timer.stage("write"):
                text = bvh.dumps(canon)
            return pipeline.Result(text, canon.num_frames, float(fps), timer, warnings)
        with timer.stage("retarget_back"):
            out = retarget.from_canonical(canon, clip.rig).replace(fps=float(fps))
        with timer.stage("write"):
            text = bvh.dumps(out)
        return pipeline.Result(text, out.num_frames, float(fps), timer, warnings, clip.rig.report())

    result = await run_inference(request, work)
    return pipeline.respond(
        request,
        result,
        engine,
        fmt=format,
        upload_name=audio.filename,
        suffix=f"dance_{name or 'auto'}",
        endpoint="/v1/dance",
    )

"""``POST /v1/stylize``: a content clip in one named style by the fast networks (one per style)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Query, Request, UploadFile

from service import pipeline
from service.deps import SettingsDep
from service.engines.fast import StylizeRequest

router = APIRouter(tags=["stylize"])


@router.post(
    "/v1/stylize",
    summary="Re-style a clip (BVH or GLB) with one named style (fast feed-forward networks)",
    response_class=pipeline.Response,
    responses=pipeline.bvh_responses("the content's format (or ?format=) on its skeleton and rate"),
)
async def stylize_clip(
    request: Request,
    settings: SettingsDep,
    content: Annotated[UploadFile, File(description="content clip (BVH or glTF)")],
    style_name: Annotated[str, Form(min_length=1, max_length=100)],
    foot_cleanup: Annotated[bool, Form()] = True,
    time_warp: Annotated[
        bool, Form(description="play the result at the style's speed (frame count changes)")
    ] = True,
    mapping: Annotated[str | None, Form(description="JSON joint-name map")] = None,
    format: Annotated[pipeline.Format | None, Query(description=pipeline.FORMAT_DOC)] = None,  # noqa: A002
) -> pipeline.Response:
    job = StylizeRequest(
        content=pipeline.upload(content, settings),
        style_name=style_name,
        foot_cleanup=foot_cleanup,
        time_warp=time_warp,
        mapping=pipeline.parse_mapping(mapping),
        format=format,
    )
    result = await pipeline.infer(request, "fast", job)
    return pipeline.respond(request, result, upload_name=content.filename)

"""``POST /v1/stylize``: a content clip in one named style by the fast networks (one per style)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Form, Request, Response

from service.deps import DataPlaneDep
from service.requests import StylizeRequest
from service.routes import answers
from service.routes.fields import ContentDep
from service.routes.known_fields import only_known_fields

router = APIRouter(tags=["stylize"])


@router.post(
    "/v1/stylize",
    dependencies=[Depends(only_known_fields)],
    summary="Re-style a clip (BVH or GLB) with one named style (fast feed-forward networks)",
    response_class=Response,
    responses=answers.clip_responses("the content's format (or ?format=) on its skeleton and rate"),
)
async def stylize_clip(
    request: Request,
    plane: DataPlaneDep,
    clip: ContentDep,
    style_name: Annotated[str, Form(min_length=1, max_length=100)],
) -> Response:
    job = StylizeRequest(clip, style_name)
    result = await plane.infer("fast", job, endpoint=answers.route_template(request))
    return answers.respond(result, upload_name=clip.filename)

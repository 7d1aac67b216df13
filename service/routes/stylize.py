"""``POST /v1/stylize``: a content clip in one named style by the fast networks (holden2017)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Query, Request, UploadFile

from service import pipeline
from service.deps import RegistryDep, SettingsDep
from service.engines.fast import FastEngine
from service.errors import NotFound, NotReady
from service.inference import run_inference
from service.metrics import StageTimer

router = APIRouter(tags=["stylize"])


def find_engine(registry, style_name: str) -> FastEngine:
    """The ready fast engine offering ``style_name``: 503 while loading, 404 if none has it."""
    engines = [e for e in registry.by_family("fast") if isinstance(e, FastEngine)]
    for engine in engines:
        if engine.has_style(style_name):
            return engine
    if not registry.ready and not engines:
        registry.require_ready()
        raise NotReady("no fast model is loaded")
    styles = sorted({s["name"] for e in engines for s in e.styles()})
    raise NotFound(f"no fast style named {style_name!r}", styles=styles)


@router.post(
    "/v1/stylize",
    summary="Re-style a BVH clip with one named style (fast feed-forward networks)",
    response_class=pipeline.Response,
    responses=pipeline.bvh_responses("BVH on the content's skeleton and frame rate (or JSON)"),
)
async def stylize_clip(
    request: Request,
    registry: RegistryDep,
    settings: SettingsDep,
    content: Annotated[UploadFile, File(description="content clip (BVH)")],
    style_name: Annotated[str, Form(min_length=1, max_length=100)],
    foot_cleanup: Annotated[bool, Form()] = True,
    mapping: Annotated[str | None, Form(description="JSON joint-name map")] = None,
    format: Annotated[pipeline.Format, Query()] = "bvh",  # noqa: A002
) -> pipeline.Response:
    engine = find_engine(registry, style_name)
    data = await pipeline.read_upload(content, settings)
    joint_map = pipeline.parse_mapping(mapping)

    def work() -> pipeline.Result:
        timer = StageTimer(engine.name)
        clip = pipeline.load_clip(data, settings, timer, mapping=joint_map)
        canon = engine.stylize(clip.canonical, style_name, timer, foot_cleanup=foot_cleanup)
        return pipeline.finish(clip, canon, timer)

    result = await run_inference(request, work)
    return pipeline.respond(
        request,
        result,
        engine,
        fmt=format,
        upload_name=content.filename,
        suffix=style_name,
        endpoint="/v1/stylize",
    )

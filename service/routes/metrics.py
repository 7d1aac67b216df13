"""``GET /metrics``: every metric in the Prometheus text format (all workers' together)."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import Response

from service import metrics

router = APIRouter(tags=["metrics"])


@router.get(
    "/metrics",
    summary="Prometheus metrics (text exposition format)",
    response_class=Response,
    responses={
        200: {
            "content": {
                "text/plain": {"schema": {"type": "string"}},
                "application/openmetrics-text": {"schema": {"type": "string"}},
            }
        }
    },
)
def get_metrics(request: Request) -> Response:
    # A plain def: reading the multiprocess files is blocking I/O, so it runs in a thread.
    body, content_type = metrics.exposition(request.headers.get("accept", ""))
    return Response(body, media_type=content_type)

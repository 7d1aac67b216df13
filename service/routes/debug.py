"""``/_debug/*``: routes for operational tests, served only with ``MOTION_DEBUG_ROUTES=1``.

``GET /_debug/sleep?seconds=2`` holds an inference thread for that long and answers
``{"slept": 2.0}``: a request that is in flight when a shutdown test sends SIGTERM.
"""

from __future__ import annotations

import time

from fastapi import APIRouter, Query

from service.deps import InferenceDep

router = APIRouter(prefix="/_debug", tags=["debug"], include_in_schema=False)


@router.get("/sleep")
async def get_sleep(runner: InferenceDep, seconds: float = Query(1.0, ge=0, le=30)) -> dict:
    started = time.perf_counter()
    await runner.run(time.sleep, seconds)
    return {"slept": round(time.perf_counter() - started, 3)}

"""Running CPU-bound work (onnxruntime, numpy) off the event loop, bounded and timed.

``await run_inference(request, fn, *args)`` (or ``await runner.run(fn, *args)`` with
:data:`service.deps.InferenceDep`) runs ``fn(*args)`` on one of
``max_concurrent_inferences`` threads and gives up after ``request_timeout_s`` with a 504
problem, so ``/healthz`` and ``/readyz`` answer while long clips are processed.

A fixed thread pool bounds the work itself, not only the waiting: a timed-out call cannot be
interrupted, but it keeps its thread until it ends, so no more than
``max_concurrent_inferences`` ever run at once (a capacity limiter would release its token
when the waiting task is cancelled, letting abandoned work pile up). The time spent queued
for a thread counts towards the timeout; a call that times out while queued never runs.
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from starlette.requests import Request

from service import metrics
from service.errors import NotReady, Timeout

T = TypeVar("T")


class InferenceRunner:
    """A bounded pool of inference threads with a per-call timeout; one per app."""

    def __init__(self, max_concurrent: int, timeout_s: float) -> None:
        self.max_concurrent = max_concurrent
        self.timeout_s = timeout_s
        self.in_flight = 0  # submitted and not yet finished or abandoned (queued + running)
        self._executor: ThreadPoolExecutor | None = None

    def start(self) -> None:
        self._executor = ThreadPoolExecutor(self.max_concurrent, thread_name_prefix="inference")

    def close(self) -> None:
        """Stop taking work; queued calls are cancelled, running ones finish on their own."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None

    async def run(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` in an inference thread (with the caller's context, so log
        lines keep the request id); :class:`Timeout` (504) after ``timeout_s``."""
        if self._executor is None:
            raise NotReady("the inference pool is not running")
        context = contextvars.copy_context()
        future = self._executor.submit(context.run, functools.partial(fn, *args, **kwargs))
        self.in_flight += 1
        metrics.IN_FLIGHT.inc()
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), self.timeout_s)
        except TimeoutError:
            future.cancel()  # only succeeds while still queued
            raise Timeout(
                f"inference did not finish within {self.timeout_s:g} s",
                limit=self.timeout_s,
            ) from None
        finally:
            self.in_flight -= 1
            metrics.IN_FLIGHT.dec()


def get_runner(request: Request) -> InferenceRunner:
    return request.app.state.runner


async def run_inference(request: Request, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> T:
    """Run ``fn(*args, **kwargs)`` through the app's :class:`InferenceRunner`."""
    return await get_runner(request).run(fn, *args, **kwargs)

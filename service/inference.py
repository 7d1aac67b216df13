"""The inference pool: CPU-bound work (onnxruntime, numpy) off the event loop, behind a
bounded queue, timed.

``await runner.run(fn, *args)`` waits for one of ``max_concurrent_inferences`` slots, then
runs ``fn(*args)`` on a thread of a pool of that size, so ``/healthz`` and ``/readyz`` answer
while long clips are processed. Overload is shed, not queued without end:

- at most ``max_queued`` calls wait for a slot; one more is a 503 ``overloaded`` problem at
  once;
- a call that cannot start within ``queue_wait_s`` is a 503 ``overloaded`` problem;
- both carry ``Retry-After`` (the wait, rounded up), and the queue depth is the gauge
  ``motion_inference_queue_depth``.

A slot is held until the work itself ends: a call that runs past ``request_timeout_s`` gets a
504, but its thread cannot be interrupted and keeps the slot, so abandoned work never piles
up beyond the pool. Uploads wait in the queue as their form left them (spooled files, on disk
beyond 1 MB), and are read and parsed only once the call starts (the engines' ``prepare``),
so the memory of waiting requests stays small.
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from service import metrics
from service.errors import NotReady, Overloaded, Timeout

T = TypeVar("T")


class InferenceRunner:
    """A bounded pool of inference threads behind a bounded queue; one per app."""

    def __init__(
        self, max_concurrent: int, timeout_s: float, queue_wait_s: float, max_queued: int
    ) -> None:
        self.max_concurrent = max_concurrent
        self.timeout_s = timeout_s
        self.queue_wait_s = queue_wait_s
        self.max_queued = max_queued
        self.queued = 0  # waiting for a slot
        self.running = 0  # holding a slot (their work not yet ended)
        self._executor: ThreadPoolExecutor | None = None
        self._slots: asyncio.Semaphore | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def start(self) -> None:
        self._executor = ThreadPoolExecutor(self.max_concurrent, thread_name_prefix="inference")
        self._slots = asyncio.Semaphore(self.max_concurrent)
        self._loop = asyncio.get_running_loop()

    def close(self) -> None:
        """Stop taking work; running calls finish on their own."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None

    def _overloaded(self, why: str) -> Overloaded:
        return Overloaded(
            why,
            headers={"Retry-After": str(max(1, math.ceil(self.queue_wait_s)))},
            queue_wait_s=self.queue_wait_s,
            max_queued=self.max_queued,
        )

    async def _acquire(self) -> None:
        assert self._slots is not None
        if self.queued >= self.max_queued and self._slots.locked():
            raise self._overloaded(
                f"{self.queued} requests are already waiting for an inference slot "
                f"(max_queued {self.max_queued})"
            )
        self.queued += 1
        metrics.QUEUE_DEPTH.inc()
        try:
            await asyncio.wait_for(self._slots.acquire(), self.queue_wait_s)
        except TimeoutError:
            raise self._overloaded(
                f"no inference slot freed within {self.queue_wait_s:g} s (queue_wait_s)"
            ) from None
        finally:
            self.queued -= 1
            metrics.QUEUE_DEPTH.dec()

    def _release(self) -> None:
        self.running -= 1
        metrics.IN_FLIGHT.dec()
        assert self._slots is not None
        self._slots.release()

    async def run(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` in an inference thread (with the caller's context, so log
        lines keep the request id): 503 :class:`Overloaded` when it cannot start in time,
        504 :class:`Timeout` when it runs past ``timeout_s``."""
        if self._executor is None or self._loop is None:
            raise NotReady("the inference pool is not running")
        await self._acquire()
        self.running += 1
        metrics.IN_FLIGHT.inc()
        context = contextvars.copy_context()
        try:
            future = self._executor.submit(context.run, functools.partial(fn, *args, **kwargs))
        except RuntimeError:  # shut down meanwhile
            self._release()
            raise NotReady("the inference pool is not running") from None
        loop = self._loop

        def release_when_done(_future: Any) -> None:
            # the slot is freed when the work ends, not when its caller stops waiting
            try:
                loop.call_soon_threadsafe(self._release)
            except RuntimeError:  # the loop has closed: nobody is left to wait for a slot
                pass

        future.add_done_callback(release_when_done)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), self.timeout_s)
        except TimeoutError:
            raise Timeout(
                f"inference did not finish within {self.timeout_s:g} s", limit=self.timeout_s
            ) from None

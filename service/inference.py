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

A freed slot goes to a waiter of the API key (:data:`service.log.key_name_var`) that holds
the fewest slots, of those the key served longest ago, and that key's earliest waiter: a
key with many requests waiting cannot make another key's request wait behind all of them.
Without keys, waiters are served in arrival order.

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
import threading
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from service import metrics
from service.errors import NotReady, Overloaded, Timeout
from service.log import key_name_var

T = TypeVar("T")


class InferenceRunner:
    """A bounded pool of inference threads behind a bounded queue; one per app.

    Slots are counted under a thread lock and handed to waiters fairly between API keys
    (the module's documentation), each waiter a future of its own event loop, so the runner works from any loop (the app's,
    or a test client's per request) and a slot is passed on from the thread whose work
    ended."""

    def __init__(
        self, max_concurrent: int, timeout_s: float, queue_wait_s: float, max_queued: int
    ) -> None:
        self.max_concurrent = max_concurrent
        self.timeout_s = timeout_s
        self.queue_wait_s = queue_wait_s
        self.max_queued = max_queued
        self.running = 0  # holding a slot (their work not yet ended)
        self._free = max_concurrent
        self._waiters: deque[tuple[asyncio.AbstractEventLoop, asyncio.Future, str | None]] = deque()
        self._held: Counter[str | None] = Counter()  # slots held, by API key name
        self._grants = 0
        self._last_grant: dict[str | None, int] = {}  # key -> number of its latest grant
        self._lock = threading.Lock()
        self._executor: ThreadPoolExecutor | None = None

    @property
    def queued(self) -> int:
        """Requests waiting for a slot."""
        return len(self._waiters)

    def start(self) -> None:
        self._executor = ThreadPoolExecutor(self.max_concurrent, thread_name_prefix="inference")

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

    async def _acquire(self, key: str | None) -> None:
        """A slot for ``key``, waiting at most ``queue_wait_s`` behind at most ``max_queued``
        others."""
        loop = asyncio.get_running_loop()
        with self._lock:
            if self._free > 0 and not self._waiters:
                self._free -= 1
                self.running += 1
                self._grant(key)
                metrics.IN_FLIGHT.inc()
                return
            if len(self._waiters) >= self.max_queued:
                raise self._overloaded(
                    f"{len(self._waiters)} requests are already waiting for an inference slot "
                    f"(max_queued {self.max_queued})"
                )
            waiter = loop.create_future()
            self._waiters.append((loop, waiter, key))
            metrics.QUEUE_DEPTH.inc()
        try:
            await asyncio.wait_for(asyncio.shield(waiter), self.queue_wait_s)
        except BaseException as exc:  # the wait ran out, or the request was cancelled
            with self._lock:
                still_waiting = (loop, waiter, key) in self._waiters
                if still_waiting:
                    self._waiters.remove((loop, waiter, key))
                    metrics.QUEUE_DEPTH.dec()
            if not still_waiting:  # granted meanwhile: the slot is ours
                if isinstance(exc, TimeoutError):
                    await waiter
                    return
                self._release(key)  # cancelled: pass it on
                raise
            if isinstance(exc, TimeoutError):
                raise self._overloaded(
                    f"no inference slot freed within {self.queue_wait_s:g} s (queue_wait_s)"
                ) from None
            raise

    def _release(self, key: str | None) -> None:
        """Pass ``key``'s slot to the next waiter, or free it (any thread)."""
        with self._lock:
            self.running -= 1
            self._held[key] -= 1
            if not self._held[key]:
                del self._held[key]
            metrics.IN_FLIGHT.dec()
            if not self._waiters:
                self._free += 1
                return
            loop, waiter, next_key = self._next_waiter()
            metrics.QUEUE_DEPTH.dec()
            self.running += 1  # the waiter's, from now on
            self._grant(next_key)
            metrics.IN_FLIGHT.inc()

        def grant() -> None:
            if not waiter.done():
                waiter.set_result(None)

        try:
            loop.call_soon_threadsafe(grant)
        except RuntimeError:  # its loop has closed: nobody will use the slot
            self._release(next_key)

    def _grant(self, key: str | None) -> None:
        self._held[key] += 1
        self._last_grant[key] = self._grants
        self._grants += 1

    def _next_waiter(self) -> tuple[asyncio.AbstractEventLoop, asyncio.Future, str | None]:
        """Take the next waiter (module documentation; under the lock)."""

        def turn(i: int) -> tuple[int, int, int]:
            key = self._waiters[i][2]
            return self._held[key], self._last_grant.get(key, -1), i

        best = min(range(len(self._waiters)), key=turn)
        waiter = self._waiters[best]
        del self._waiters[best]
        return waiter

    async def run(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> T:
        """``fn(*args, **kwargs)`` in an inference thread (with the caller's context, so log
        lines keep the request id): 503 :class:`Overloaded` when it cannot start in time,
        504 :class:`Timeout` when it runs past ``timeout_s``."""
        if self._executor is None:
            raise NotReady("the inference pool is not running")
        key = key_name_var.get()
        await self._acquire(key)
        context = contextvars.copy_context()
        try:
            future = self._executor.submit(context.run, functools.partial(fn, *args, **kwargs))
        except RuntimeError:  # shut down meanwhile
            self._release(key)
            raise NotReady("the inference pool is not running") from None
        # the slot is passed on when the work ends, not when its caller stops waiting
        future.add_done_callback(lambda _: self._release(key))
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), self.timeout_s)
        except TimeoutError:
            raise Timeout(
                f"inference did not finish within {self.timeout_s:g} s", limit=self.timeout_s
            ) from None

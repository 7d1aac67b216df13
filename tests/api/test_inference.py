"""The inference pool: off the event loop, bounded by max_concurrent_inferences, 504 on
timeout, and overload shed as 503 with Retry-After (queue_wait_s, max_queued)."""

from __future__ import annotations

import threading
import time

from fastapi import FastAPI, Request

from service.config import Settings
from service.deps import InferenceDep
from service.log import request_id_var
from tests.api.helpers import assert_problem


class Work:
    """Blocking work that records how many copies run at once."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.lock = threading.Lock()
        self.running = 0
        self.peak = 0
        self.started = threading.Semaphore(0)

    def __call__(self, seconds: float) -> str:
        with self.lock:
            self.running += 1
            self.peak = max(self.peak, self.running)
        self.started.release()
        try:
            self.release.wait(seconds)
            return request_id_var.get()
        finally:
            with self.lock:
                self.running -= 1


def add_inference_routes(app: FastAPI, work: Work) -> None:
    @app.get("/_test/work")
    async def do_work(request: Request, seconds: float = 5.0):
        return {"request_id": await request.app.state.runner.run(work, seconds)}

    @app.get("/_test/work-dep")
    async def do_work_dep(runner: InferenceDep, seconds: float = 5.0):
        return {"request_id": await runner.run(work, seconds)}


def test_inference_runs_in_a_thread_with_the_request_id(make_client):
    work = Work()
    work.release.set()
    client = make_client(setup=lambda app: add_inference_routes(app, work))
    for path in ("/_test/work", "/_test/work-dep"):
        response = client.get(path, headers={"X-Request-Id": "inf-1"})
        assert response.json() == {"request_id": "inf-1"}


def test_timeout_is_504_problem(make_client):
    work = Work()
    client = make_client(
        Settings(request_timeout_s=0.2), setup=lambda app: add_inference_routes(app, work)
    )
    started = time.perf_counter()
    body = assert_problem(client.get("/_test/work", params={"seconds": 2}), 504, "timeout")
    assert time.perf_counter() - started < 1.5
    assert body["limit"] == 0.2
    work.release.set()


def test_health_answers_while_inference_runs_and_concurrency_is_bounded(make_client):
    work = Work()
    client = make_client(
        Settings(max_concurrent_inferences=1, request_timeout_s=10),
        setup=lambda app: add_inference_routes(app, work),
    )
    results: list[int] = []

    def call() -> None:
        results.append(client.get("/_test/work", params={"seconds": 10}).status_code)

    threads = [threading.Thread(target=call) for _ in range(3)]
    for thread in threads:
        thread.start()
    try:
        assert work.started.acquire(timeout=5)  # one is running, the others wait for the thread
        # the other two requests reach the runner on their own threads, in their own time
        runner = client.app.state.runner
        deadline = time.perf_counter() + 5
        while runner.running + runner.queued < 3 and time.perf_counter() < deadline:
            time.sleep(0.01)
        assert (runner.running, runner.queued) == (1, 2)

        started = time.perf_counter()
        assert client.get("/healthz").status_code == 200
        assert client.get("/readyz").status_code == 200
        assert time.perf_counter() - started < 1.0
        assert (runner.running, runner.queued) == (1, 2)  # nobody finished meanwhile
    finally:  # a failure above must not leave three requests blocked for the next tests
        work.release.set()
        for thread in threads:
            thread.join(timeout=10)
    assert results == [200, 200, 200]
    assert work.peak == 1


def wait_for(predicate, seconds: float = 5.0) -> None:
    deadline = time.perf_counter() + seconds
    while not predicate() and time.perf_counter() < deadline:
        time.sleep(0.01)
    assert predicate()


def test_a_request_that_cannot_start_in_time_is_503_with_retry_after(make_client):
    work = Work()
    client = make_client(
        Settings(max_concurrent_inferences=1, queue_wait_s=0.3, request_timeout_s=10),
        setup=lambda app: add_inference_routes(app, work),
    )
    holder = threading.Thread(
        target=client.get, args=("/_test/work",), kwargs={"params": {"seconds": 10}}
    )
    holder.start()
    try:
        assert work.started.acquire(timeout=5)
        started = time.perf_counter()
        response = client.get("/_test/work", params={"seconds": 0})
        waited = time.perf_counter() - started
        body = assert_problem(response, 503, "overloaded")
        assert response.headers["retry-after"] == "1"
        assert 0.25 < waited < 2.0
        assert body["queue_wait_s"] == 0.3
        assert work.peak == 1
    finally:
        work.release.set()
        holder.join(timeout=10)
    # the slot is free again: the next request runs
    assert client.get("/_test/work", params={"seconds": 0}).status_code == 200


def test_a_full_queue_refuses_at_once_and_its_depth_is_a_metric(make_client):
    work = Work()
    client = make_client(
        Settings(max_concurrent_inferences=1, max_queued=2, queue_wait_s=20, request_timeout_s=30),
        setup=lambda app: add_inference_routes(app, work),
    )
    runner = client.app.state.runner
    statuses: list[int] = []

    def call() -> None:
        statuses.append(client.get("/_test/work", params={"seconds": 20}).status_code)

    threads = [threading.Thread(target=call) for _ in range(3)]
    for thread in threads:
        thread.start()
    try:
        wait_for(lambda: runner.running == 1 and runner.queued == 2)
        metrics = client.get("/metrics").text
        assert "motion_inference_queue_depth 2.0" in metrics
        assert "motion_inferences_in_flight 1.0" in metrics
        started = time.perf_counter()
        response = client.get("/_test/work", params={"seconds": 0})
        assert_problem(response, 503, "overloaded")
        assert "max_queued" in response.json()["detail"]
        assert time.perf_counter() - started < 1.0
    finally:
        work.release.set()
        for thread in threads:
            thread.join(timeout=10)
    assert statuses == [200, 200, 200]
    assert work.peak == 1


def test_a_timed_out_call_keeps_its_slot_until_its_work_ends(make_client):
    work = Work()
    client = make_client(
        Settings(max_concurrent_inferences=1, request_timeout_s=0.2, queue_wait_s=0.3),
        setup=lambda app: add_inference_routes(app, work),
    )
    assert_problem(client.get("/_test/work", params={"seconds": 5}), 504, "timeout")
    # the abandoned work still runs and holds the only slot: the next request is shed
    assert_problem(client.get("/_test/work", params={"seconds": 0}), 503, "overloaded")
    work.release.set()
    wait_for(lambda: client.app.state.runner.running == 0)
    assert client.get("/_test/work", params={"seconds": 0}).status_code == 200
    assert work.peak == 1


def test_the_runner_serves_any_event_loop_and_a_cancelled_wait_frees_its_place():
    import asyncio

    from service.inference import InferenceRunner

    runner = InferenceRunner(1, timeout_s=5, queue_wait_s=5, max_queued=4)
    runner.start()  # outside any loop, as a test harness without lifespan does
    try:
        assert asyncio.run(runner.run(sum, [1, 2])) == 3
        assert asyncio.run(runner.run(sum, [3, 4])) == 7  # another loop

        async def cancel_a_waiter() -> None:
            gate = threading.Event()
            holder = asyncio.ensure_future(runner.run(gate.wait, 5))
            await asyncio.sleep(0.05)
            waiter = asyncio.ensure_future(runner.run(sum, [1]))
            await asyncio.sleep(0.05)
            assert (runner.running, runner.queued) == (1, 1)
            waiter.cancel()
            await asyncio.sleep(0.05)
            assert runner.queued == 0
            gate.set()
            await holder
            assert await runner.run(sum, [5]) == 5  # the slot came back

        asyncio.run(cancel_a_waiter())
        assert (runner.running, runner.queued) == (0, 0)
    finally:
        runner.close()

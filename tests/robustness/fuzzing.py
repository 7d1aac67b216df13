"""Helpers shared by the fuzz tests: :func:`fuzz_settings` and :func:`time_limit`.

``make test`` runs a few hundred examples per target (derandomized when ``CI`` is set, so
CI runs are reproducible); ``MOTION_FUZZ=1 pytest tests/robustness`` runs 20x as many, with
fresh random seeds. Each example also runs under :func:`time_limit`: parsers must never hang.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import timedelta

from hypothesis import HealthCheck, settings

FUZZ = os.environ.get("MOTION_FUZZ") == "1"


def fuzz_settings(examples: int, **overrides) -> settings:
    """Settings for one fuzz target: ``examples`` examples (20x under ``MOTION_FUZZ=1``), a
    5 s deadline per example, derandomized when ``CI`` is set (reproducible CI runs)."""
    options = {
        "max_examples": examples * 20 if FUZZ else examples,
        "deadline": timedelta(seconds=5),
        "derandomize": bool(os.environ.get("CI")) and not FUZZ,
        "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
        "print_blob": True,
    }
    options.update(overrides)
    return settings(**options)


class Hang(AssertionError):
    """A parser ran past its time limit."""


@contextmanager
def time_limit(seconds: float, what: str = "call") -> Iterator[None]:
    """Fail with :class:`Hang` if the block runs past ``seconds`` (SIGALRM, main thread).

    A hang inside C code that never returns to Python cannot be interrupted that way, so a
    second watchdog dumps every thread's stack and ends the process at 4x the limit: a
    hang fails loudly instead of stalling CI.
    """

    def on_alarm(signum, frame):
        raise Hang(f"{what} did not finish within {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    faulthandler.dump_traceback_later(seconds * 4, exit=True, file=sys.stderr)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        faulthandler.cancel_dump_traceback_later()

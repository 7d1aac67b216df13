"""Per-key limits shared by the worker processes of one replica: a request rate (a token
bucket) and requests in progress, over small files in one folder
(``MOTION_KEY_STATE_DIR``; ``python -m service`` makes a fresh one for its workers).

- Rate: ``NAME.rate`` holds the key's bucket (tokens, time), 16 bytes read and written under
  ``flock``, so each request of any worker takes one token; the bucket holds ``burst``
  tokens and refills at ``per_minute / 60`` a second. Empty: refused with the seconds until
  the next token.
- In progress: ``NAME.slot0`` .. ``NAME.slot{N-1}``; a request holds one of them with a
  non-blocking ``flock`` until its response is sent. The kernel drops the lock of a process
  that dies, so a crashed worker never keeps a slot.

Each key has its own bucket and slots, so a key at its limits takes nothing from another.
Limits are per replica: N replicas let a key make N times the rate.
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import os
import struct
import time
from pathlib import Path

_BUCKET = struct.Struct("<dd")  # tokens, CLOCK_MONOTONIC seconds (one clock for every process)


class Slot:
    """One request-in-progress slot of a key, held until :meth:`release`."""

    def __init__(self, owner: _KeySlots | None, index: int) -> None:
        self._owner, self._index = owner, index

    def release(self) -> None:
        if self._owner is not None:
            self._owner.release(self._index)
            self._owner = None


class _KeySlots:
    """This process's handles on one key's slot files."""

    def __init__(self, folder: Path, name: str, count: int) -> None:
        self.fds = [
            os.open(folder / f"{name}.slot{i}", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
            for i in range(count)
        ]
        self.busy = [False] * count  # held by this process (its fd's lock)

    def acquire(self) -> Slot | None:
        for i, fd in enumerate(self.fds):
            if self.busy[i]:
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue  # another worker holds it
            self.busy[i] = True
            return Slot(self, i)
        return None

    def release(self, index: int) -> None:
        fcntl.flock(self.fds[index], fcntl.LOCK_UN)
        self.busy[index] = False

    def close(self) -> None:
        for fd in self.fds:
            with contextlib.suppress(OSError):
                os.close(fd)


class KeyLimits:
    """Rate and concurrency limits per key name, shared through ``folder`` (made if
    missing). ``per_minute`` 0 or ``max_concurrent`` 0 turns that limit off."""

    def __init__(self, folder: Path, per_minute: float, burst: int, max_concurrent: int) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.per_second = per_minute / 60.0
        self.burst = max(1, burst)
        self.max_concurrent = max_concurrent
        self._buckets: dict[str, int] = {}
        self._slots: dict[str, _KeySlots] = {}

    def take(self, name: str) -> float:
        """Take one request from ``name``'s rate: 0 when allowed, else the seconds until a
        request would be."""
        if self.per_second <= 0:
            return 0.0
        fd = self._buckets.get(name)
        if fd is None:
            path = self.folder / f"{name}.rate"
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
            self._buckets[name] = fd
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            now = time.monotonic()
            data = os.pread(fd, _BUCKET.size, 0)
            if len(data) == _BUCKET.size:
                tokens, then = _BUCKET.unpack(data)
                if not (math.isfinite(tokens) and then <= now):  # a clock from before a boot
                    tokens, then = float(self.burst), now
            else:
                tokens, then = float(self.burst), now
            tokens = min(float(self.burst), tokens + (now - then) * self.per_second)
            if tokens >= 1.0:
                os.pwrite(fd, _BUCKET.pack(tokens - 1.0, now), 0)
                return 0.0
            os.pwrite(fd, _BUCKET.pack(tokens, now), 0)
            return (1.0 - tokens) / self.per_second
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)

    def acquire(self, name: str) -> Slot | None:
        """A request-in-progress slot of ``name``, or None when all are held (by any worker).
        With no concurrency limit, a slot that holds nothing."""
        if self.max_concurrent <= 0:
            return Slot(None, 0)
        slots = self._slots.get(name)
        if slots is None:
            slots = self._slots[name] = _KeySlots(self.folder, name, self.max_concurrent)
        return slots.acquire()

    def close(self) -> None:
        for fd in self._buckets.values():
            with contextlib.suppress(OSError):
                os.close(fd)
        for slots in self._slots.values():
            slots.close()
        self._buckets.clear()
        self._slots.clear()

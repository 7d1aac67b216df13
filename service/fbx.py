"""FBX in and out through Blender as a Python module (``bpy``, the ``fbx`` extra).

:func:`read` gives an :class:`FbxFile`: the motion of the file's armature (as
:mod:`motion.armature` reads what Blender's importer made of it) and :meth:`FbxFile.write`,
the same file with a new motion keyed onto its bones, exported by Blender. bpy runs in a
pool of warm worker processes (:mod:`service.fbx_worker`), never in a request's thread: it
is neither thread-safe nor re-entrant, and a file that hangs or crashes Blender costs one
worker, which is replaced. One pool per service process, started with the app
(:func:`start`, ``fbx_workers`` of them) and shared by every app in the process; a call
waits for a free worker, preferring the one that holds the file already (writing the
answer into the file a request has just read does not import it again).

Limits are those of every clip: the upload size (middleware), ``max_frames`` (counted
before Blender samples a frame: 413) and ``request_timeout_s`` for each call into Blender
(past it the worker is killed and replaced: 504). Without bpy (or with ``fbx_workers=0``)
an FBX is a 415 problem that says how to enable it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import socket
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

from motion import armature as A
from motion import fbx_rekey
from motion.errors import MotionError
from motion.skeleton import Motion
from service.errors import Timeout, UnsupportedMediaType

logger = logging.getLogger(__name__)

REPO = Path(__file__).resolve().parent.parent
FBX_MAGIC = b"Kaydara FBX Binary  \x00"
ENABLE = (
    "FBX is read and written by Blender as a Python module, which this service does not "
    "have: install the fbx extra (pip install 'motion-style[fbx]', bpy 4.2 on CPython "
    "3.11) and keep fbx_workers (MOTION_FBX_WORKERS) >= 1; or send the character as .glb "
    "or .bvh"
)
START_TIMEOUT_S = 120.0


def installed() -> bool:
    """Whether Blender as a Python module (``bpy``) can be imported here."""
    return importlib.util.find_spec("bpy") is not None


def is_fbx(data: bytes) -> bool:
    """Whether ``data`` is an FBX file: binary (Kaydara's magic) or ASCII (its header)."""
    return data.startswith(FBX_MAGIC) or data.lstrip(b"\xef\xbb\xbf \t\r\n")[:5] == b"; FBX"


class _Worker:
    """One Blender process and the connection to it."""

    def __init__(self) -> None:
        parent, child = socket.socketpair()
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "service.fbx_worker", str(child.fileno())],
            pass_fds=[child.fileno()],
            env=env,
            stdin=subprocess.DEVNULL,
        )
        child.close()
        self.connection = Connection(parent.detach())
        self.digest: str | None = None  # the file it holds
        self.used = 0.0
        self.ready = False

    def wait_ready(self, timeout: float) -> None:
        if not self.connection.poll(timeout):
            raise RuntimeError(f"Blender did not start within {timeout:g} s")
        if self.connection.recv() != ("ready",):
            raise RuntimeError("Blender sent an unexpected greeting")
        self.ready = True

    def close(self) -> None:
        try:
            self.connection.close()
        finally:
            if self.process.poll() is None:
                self.process.kill()
            self.process.wait()


class BlenderPool:
    """``size`` warm Blender worker processes; :meth:`call` runs one operation in one."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._idle: list[_Worker] = []
        self._condition = threading.Condition()
        self._closed = False

    def start(self) -> None:
        """Start the workers (in parallel) and wait until each has loaded Blender."""
        began = time.monotonic()
        workers = [_Worker() for _ in range(self.size)]
        for w in workers:
            self._give_back_when_ready(w, "start")
        logger.info(
            "FBX: %d of %d Blender workers ready in %.1f s",
            len(self._idle), self.size, time.monotonic() - began,
        )  # fmt: skip

    def close(self) -> None:
        with self._condition:
            self._closed = True
            workers, self._idle = self._idle, []
        for w in workers:
            w.close()

    def _take(self, digest: str, timeout: float) -> _Worker:
        deadline = time.monotonic() + timeout
        with self._condition:
            while not self._idle:
                left = deadline - time.monotonic()
                if self._closed or left <= 0 or not self._condition.wait(left):
                    raise Timeout(f"no Blender worker was free within {timeout:g} s", limit=timeout)
            chosen = next((w for w in self._idle if w.digest == digest), None)
            chosen = chosen or min(self._idle, key=lambda w: w.used)
            self._idle.remove(chosen)
            return chosen

    def _give_back(self, worker: _Worker) -> None:
        with self._condition:
            if self._closed:
                worker.close()
                return
            self._idle.append(worker)
            self._condition.notify()

    def _replace(self, worker: _Worker) -> None:
        """Kill ``worker`` and start another in the background."""
        worker.close()

        threading.Thread(
            target=lambda: self._give_back_when_ready(_Worker(), "restart"),
            name="blender-respawn",
            daemon=True,
        ).start()

    def _give_back_when_ready(self, worker: _Worker, what: str) -> None:
        """Into the pool once Blender has loaded; closed, and logged, when it does not."""
        try:
            worker.wait_ready(START_TIMEOUT_S)
        except (RuntimeError, EOFError, OSError) as exc:
            logger.error("a Blender worker did not %s: %s", what, exc)
            worker.close()
            return
        self._give_back(worker)

    def call(self, op: str, data: bytes, timeout: float, **kwargs):
        """``op`` of :mod:`service.fbx_worker` on the FBX file ``data``: its value, or the
        worker's :class:`MotionError`; 504 :class:`Timeout` past ``timeout`` seconds."""
        digest = hashlib.sha256(data).hexdigest()
        start = time.monotonic()
        worker = self._take(digest, timeout)
        left = max(timeout - (time.monotonic() - start), 0.001)
        try:
            worker.connection.send((op, {"data": data, **kwargs}))
            if not worker.connection.poll(left):
                self._replace(worker)
                raise Timeout(f"Blender did not finish within {timeout:g} s", limit=timeout)
            answer = worker.connection.recv()
        except (EOFError, OSError):
            self._replace(worker)
            raise MotionError("Blender stopped while handling the FBX file") from None
        worker.digest, worker.used = digest, time.monotonic()
        self._give_back(worker)
        if answer[0] == "error":
            raise MotionError(answer[2], kind=answer[1])
        return answer[1]


_pool: BlenderPool | None = None
_pool_lock = threading.Lock()


def start(workers: int) -> BlenderPool | None:
    """The process's pool, started with ``workers`` workers the first time (blocking until
    they are warm); None without bpy or with ``workers`` 0."""
    global _pool
    if workers < 1 or not installed():
        return None
    with _pool_lock:
        if _pool is None:
            _pool = BlenderPool(workers)
            _pool.start()
        return _pool


def _require_pool(workers: int) -> BlenderPool:
    pool = start(workers)
    if pool is None:
        raise UnsupportedMediaType(ENABLE, requires="fbx extra")
    return pool


class FbxFile:
    """A read FBX file: ``motion`` (its armature's animation) and :meth:`write`."""

    def __init__(
        self,
        data: bytes,
        armature: A.Armature,
        motion: Motion,
        workers: int,
        timeout: float,
        first_pose: np.ndarray | None = None,
    ) -> None:
        self.data = data
        self.armature = armature
        self.motion = motion
        self.first_pose = first_pose  # the bones as Blender read the first frame (animated files)
        self._workers = workers
        self._timeout = timeout

    def write(self, motion: Motion) -> bytes:
        """FBX bytes of this file with ``motion`` (on its joints) as its armature's action:
        keyed straight into the file's bytes where :mod:`motion.fbx_rekey` can, else
        exported by Blender."""
        if self.first_pose is not None:
            plan = fbx_rekey.plan(
                self.data, self.armature.names, self.armature.parents, self.first_pose
            )
            if isinstance(plan, fbx_rekey.Plan):
                return plan.write(A.pose_matrices(self.armature, motion), float(motion.fps))
            logger.info("FBX answer exported by Blender: %s", plan)
        location, rotation = A.to_basis(self.armature, motion)
        pool = _require_pool(self._workers)
        return pool.call(
            "write", self.data, self._timeout, location=location, rotation=rotation,
            fps=float(motion.fps),
        )  # fmt: skip


def read(
    data: bytes,
    *,
    workers: int,
    timeout: float,
    max_frames: int,
    rest_if_unanimated: bool = False,
) -> FbxFile:
    """Parse FBX ``data`` in a Blender worker: 415 without bpy, 400 for a file Blender cannot
    read (ASCII FBX included), 422 without an armature (or, unless ``rest_if_unanimated``,
    without its animation: then one frame of its rest pose), 413 over ``max_frames``."""
    pool = _require_pool(workers)
    answer = pool.call(
        "read", data, timeout, max_frames=max_frames, rest_if_unanimated=rest_if_unanimated
    )
    armature = A.Armature(**answer["armature"])
    motion = A.to_motion(armature, answer["bones"], answer["objects"], answer["fps"])
    # a file whose armature object moves, or has no animation, is written by Blender
    still = answer["animated"] and answer["objects"] is None
    first = np.asarray(answer["bones"][0], dtype=np.float64) if still else None
    return FbxFile(data, armature, motion, workers, timeout, first)

"""``python -m service [--host H] [--port P] [--workers N] [--log-level L]``: run uvicorn.
``python -m service keys add|list|revoke ...``: the API keys (:mod:`service.keys_cli`).

Options override the ``MOTION_*`` environment; they are passed on to the worker processes
through that environment, since each worker builds its own app with ``create_app()``.
SIGINT/SIGTERM shut down gracefully (uvicorn's own handling): no new connections, in-flight
requests get up to ``request_timeout_s`` to finish.

Metrics of several workers: see :func:`prepare_metrics_dir`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

from pydantic import ValidationError


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m service",
        description="Serve the motion-style REST API. Other settings: MOTION_* variables.",
    )
    parser.add_argument("--host", help="bind address (default: $MOTION_HOST or 127.0.0.1)")
    parser.add_argument("--port", type=int, help="port (default: $MOTION_PORT or 8000)")
    parser.add_argument(
        "--workers", type=int, help="worker processes (default: $MOTION_WORKERS or 1)"
    )
    parser.add_argument(
        "--log-level",
        choices=["critical", "error", "warning", "info", "debug"],
        help="(default: $MOTION_LOG_LEVEL or info)",
    )
    return parser.parse_args(argv)


def prepare_metrics_dir(workers: int) -> str | None:
    """Make ``PROMETHEUS_MULTIPROC_DIR`` ready before any worker imports prometheus-client.

    Set: create the folder and delete the ``*.db`` files an earlier run left there (their
    counts would add to this run's). Unset with several workers: point it at a new temporary
    folder, since one worker's registry only knows the requests that worker answered. Unset
    with one worker: nothing (the process's own registry is exact). Returns the folder.
    """
    path = os.environ.get("PROMETHEUS_MULTIPROC_DIR")
    if not path:
        if workers <= 1:
            return None
        path = tempfile.mkdtemp(prefix="motion-metrics-")
        os.environ["PROMETHEUS_MULTIPROC_DIR"] = path
    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    for stale in folder.glob("*.db"):
        stale.unlink(missing_ok=True)
    return path


def prepare_key_state_dir() -> str | None:
    """Point ``MOTION_KEY_STATE_DIR`` at a folder every worker of this replica shares, so
    each key's limits count the requests of all of them (:mod:`service.key_limits`).
    Unset, a new temporary folder, returned so that it is removed at the end."""
    path = os.environ.get("MOTION_KEY_STATE_DIR")
    if path:
        Path(path).mkdir(parents=True, exist_ok=True)
        return None
    path = tempfile.mkdtemp(prefix="motion-keys-")
    os.environ["MOTION_KEY_STATE_DIR"] = path
    return path


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["keys"]:
        from service import keys_cli

        sys.exit(keys_cli.main(argv[1:]))
    args = parse_args(argv)
    overrides = {k: v for k, v in vars(args).items() if v is not None}

    from service.config import Settings

    try:
        settings = Settings(**overrides)
    except ValidationError as exc:
        sys.exit(f"invalid settings:\n{exc}")
    for key, value in overrides.items():
        os.environ[f"MOTION_{key.upper()}"] = str(value)

    prepare_metrics_dir(settings.workers)
    if settings.api_keys_file is not None:
        from service.api_keys import KeysFile, KeysFileError

        try:
            KeysFile(settings.api_keys_file)
        except KeysFileError as exc:
            sys.exit(str(exc))
        made_key_state_dir = prepare_key_state_dir()
    else:
        made_key_state_dir = None
    if settings.workers > 1:
        # compiled once here: workers compiling at once into one numba cache can leave
        # it inconsistent, and a worker that then loads it crashes
        from motion import compiled

        compiled.warm()

    import uvicorn

    from service.log import log_config

    uvicorn.run(
        "service.main:create_app",
        factory=True,
        host=settings.host,
        port=settings.port,
        workers=settings.workers,
        log_config=log_config(settings.log_level, settings.log_format),
        log_level=settings.log_level,
        access_log=False,  # the request-context middleware logs each request with its id
        timeout_graceful_shutdown=int(settings.request_timeout_s) + 1,
    )
    if made_key_state_dir is not None:
        shutil.rmtree(made_key_state_dir, ignore_errors=True)


if __name__ == "__main__":
    main()

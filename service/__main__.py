"""``python -m service [--host H] [--port P] [--workers N] [--log-level L]``: run uvicorn.

Options override the ``MOTION_*`` environment; they are passed on to the worker processes
through that environment, since each worker builds its own app with ``create_app()``.
SIGINT/SIGTERM shut down gracefully (uvicorn's own handling): no new connections, in-flight
requests get up to ``request_timeout_s`` to finish.
"""

from __future__ import annotations

import argparse
import os
import sys

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


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    overrides = {k: v for k, v in vars(args).items() if v is not None}

    from service.config import Settings

    try:
        settings = Settings(**overrides)
    except ValidationError as exc:
        sys.exit(f"invalid settings:\n{exc}")
    for key, value in overrides.items():
        os.environ[f"MOTION_{key.upper()}"] = str(value)

    import uvicorn

    from service.log import log_config

    uvicorn.run(
        "service.main:create_app",
        factory=True,
        host=settings.host,
        port=settings.port,
        workers=settings.workers,
        log_config=log_config(settings.log_level),
        log_level=settings.log_level,
        access_log=False,  # the request-context middleware logs each request with its id
        timeout_graceful_shutdown=int(settings.request_timeout_s) + 1,
    )


if __name__ == "__main__":
    main()

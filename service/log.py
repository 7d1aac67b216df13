"""Logging: every line carries the request id of the request it belongs to (``-`` outside one).

The request-context middleware sets :data:`request_id_var`; :class:`RequestIdFilter` copies it
onto each record, and work handed to inference threads keeps it (contexts are copied).

Two formats (``MOTION_LOG_FORMAT``): ``text`` for people, and ``json`` (one JSON object per
line, for log collectors) with ``ts``, ``level``, ``logger``, ``message``, ``request_id`` and
whatever the call passed as ``extra=``; the access line of each request adds ``method``,
``path``, ``status`` and ``duration_ms``::

    {"ts": "2025-01-30T12:00:00.123Z", "level": "INFO", "logger": "service.access",
     "message": "GET /healthz 200 0.4ms", "request_id": "4f0c...", "method": "GET",
     "path": "/healthz", "status": 200, "duration_ms": 0.4}
"""

from __future__ import annotations

import json
import logging
import time
from contextvars import ContextVar
from typing import Any

request_id_var: ContextVar[str] = ContextVar("request_id", default="-")
# the name of the request's API key (service.auth sets it; never the key): log lines of the
# request carry it as ``key``, and the inference pool shares its slots fairly between keys
key_name_var: ContextVar[str | None] = ContextVar("key_name", default=None)

FORMAT = "%(asctime)s %(levelname)s %(name)s [%(request_id)s] %(message)s"


class RequestIdFilter(logging.Filter):
    """Adds ``record.request_id`` (the current request's id, or ``-``)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not hasattr(record, "request_id"):
            record.request_id = request_id_var.get()
        key = key_name_var.get()
        if key is not None and not hasattr(record, "key"):
            record.key = key
        return True


# Attributes every LogRecord has; anything else on a record came from ``extra=``.
_RECORD_ATTRS = frozenset(vars(logging.LogRecord("", 0, "", 0, "", None, None))) | {
    "message",
    "asctime",
    "taskName",
    "color_message",  # uvicorn's ANSI-coloured copy of the message
}


class JsonFormatter(logging.Formatter):
    """One JSON object per line: ``ts`` (UTC, ms), ``level``, ``logger``, ``message``,
    ``request_id``, the record's ``extra=`` fields, and ``exc`` (the traceback) if any."""

    def format(self, record: logging.LogRecord) -> str:
        seconds = int(record.created)
        millis = int((record.created - seconds) * 1000)
        out: dict[str, Any] = {
            "ts": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(seconds)) + f".{millis:03d}Z",
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
            "request_id": getattr(record, "request_id", request_id_var.get()),
        }
        for key, value in vars(record).items():
            if key not in _RECORD_ATTRS and key not in out:
                out[key] = value
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        elif record.stack_info:
            out["stack"] = self.formatStack(record.stack_info)
        return json.dumps(out, default=str, ensure_ascii=False)


def log_config(level: str = "info", fmt: str = "text") -> dict[str, Any]:
    """A ``logging.config.dictConfig`` for uvicorn and the service, request ids included;
    ``fmt`` is ``"text"`` or ``"json"`` (JSON lines)."""
    if fmt not in ("text", "json"):
        raise ValueError(f"log format must be 'text' or 'json', not {fmt!r}")
    handler = {
        "class": "logging.StreamHandler",
        "formatter": fmt,
        "filters": ["request_id"],
        "stream": "ext://sys.stderr",
    }
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "filters": {"request_id": {"()": RequestIdFilter}},
        "formatters": {"text": {"format": FORMAT}, "json": {"()": JsonFormatter}},
        "handlers": {"default": handler},
        "loggers": {
            "service": {"handlers": ["default"], "level": level.upper(), "propagate": False},
            "uvicorn": {"handlers": ["default"], "level": level.upper(), "propagate": False},
            "uvicorn.access": {"level": "WARNING"},
        },
    }

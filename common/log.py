"""Structured logging: one line per event, ``key=value`` pairs, with service, instance and request id.

An exception adds its last line (``exc=...``); at debug level (``OBJSCAN_LOG_LEVEL=debug``) the full
traceback follows on indented lines.

The request id travels in a context variable, so every line a handler logs (and every line logged in
code it calls) names the request it belongs to without threading an argument through every call.
"""

from __future__ import annotations

import contextvars
import logging
import os
import sys
import time

request_id: contextvars.ContextVar[str] = contextvars.ContextVar("request_id", default="-")

_service = "-"
_instance = "-"


class _KeyValueFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        ts = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created)) + f".{int(record.msecs):03d}Z"
        fields = getattr(record, "fields", None) or {}
        extra = "".join(f" {k}={_fmt(v)}" for k, v in fields.items())
        line = (f"{ts} {record.levelname:<5} service={_service} instance={_instance} "
                f"req={request_id.get()} {record.getMessage()}{extra}")
        if record.exc_info:
            trace = self.formatException(record.exc_info).splitlines()
            line += " exc=" + _fmt(trace[-1])
            if logging.getLogger().isEnabledFor(logging.DEBUG):
                # at debug level the whole traceback, indented so a line-based reader keeps it with its event
                line += "\n" + "\n".join("    " + t for t in trace)
        return line


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    s = str(v)
    return f'"{s}"' if (" " in s or not s) else s


def setup_logging(service: str, instance: str, level: str | None = None) -> None:
    """Configure the root logger for one service process (stderr, one line per event)."""
    global _service, _instance
    _service, _instance = service, instance
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_KeyValueFormatter())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel((level or os.environ.get("OBJSCAN_LOG_LEVEL", "INFO")).upper())


def event(logger: logging.Logger, message: str, level: int = logging.INFO, /, **fields: object) -> None:
    """Log one event with structured fields: ``event(log, "capture done", ms=12.3, seq=4)``."""
    logger.log(level, message, extra={"fields": fields})

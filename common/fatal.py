"""A service that cannot start says why, typed, where the process that started it can read it.

Why: a service dying in its start-up (the twin given an object it cannot load, a bad configuration file)
used to leave only an exit code to its starter, which could say no more than "sim exited with code 1; see
its log", while the real reason (``[object_not_found] unknown object ...``) sat in that log. The starter
(``common/launcher.py``) now names a file per process in ``$OBJSCAN_FATAL_FILE``; ``run_service`` writes the
error that ended the start there as one JSON object ``{"service", "code", "message", "detail"}``, and the
starter raises it again as a ``ServiceStartError`` with the service's own code and message.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from common.atomic import atomic_write_bytes
from common.errors import ObjscanError, ServiceStartError

FATAL_FILE_ENV = "OBJSCAN_FATAL_FILE"


def fatal_payload(service: str, exc: BaseException) -> dict[str, Any]:
    """What a dying service says: its typed error, or ``internal`` with the exception's type for any other."""
    if isinstance(exc, ObjscanError):
        return {"service": service, "code": exc.code, "message": exc.message, "detail": _plain(exc.detail)}
    return {"service": service, "code": "internal", "message": f"{type(exc).__name__}: {exc}", "detail": {}}


def write_fatal(service: str, exc: BaseException, path: str | Path | None = None) -> Path | None:
    """Write ``exc`` to ``path`` (default ``$OBJSCAN_FATAL_FILE``); nothing when no file is named.

    Never raises: the service is already failing, and its traceback still goes to its log."""
    target = path or os.environ.get(FATAL_FILE_ENV)
    if not target:
        return None
    try:
        atomic_write_bytes(Path(target), json.dumps(fatal_payload(service, exc), default=str).encode())
    except OSError:
        return None
    return Path(target)


def read_fatal(path: str | Path | None) -> dict[str, Any] | None:
    """The error a dead service wrote to ``path``, or None (none written, or unreadable)."""
    if not path:
        return None
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or not isinstance(doc.get("code"), str) or not isinstance(doc.get("message"), str):
        return None
    return doc


def start_error(label: str, returncode: int | None, fatal: dict[str, Any] | None,
                log: Path | None = None, *, starting: bool = True) -> ServiceStartError:
    """The error for process ``label`` that ended (while starting, or later when not ``starting``): its own
    typed error when it wrote one."""
    detail: dict[str, Any] = {"service": label, "exit_code": returncode}
    if log is not None:
        detail["log"] = str(log)
    if fatal is not None:
        return ServiceStartError(f"{label} {'could not start' if starting else 'stopped'}: {fatal['message']}",
                                 code=fatal["code"], detail={**(fatal.get("detail") or {}), **detail})
    where = f"; see {log}" if log is not None else ""
    return ServiceStartError(f"{label} exited with code {returncode}{' before it was live' if starting else ''}"
                             f"{where}", detail=detail)


def _plain(detail: Any) -> Any:
    """A detail map as JSON can hold it (numpy arrays and scalars as plain values)."""
    return json.loads(json.dumps(detail, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v)))

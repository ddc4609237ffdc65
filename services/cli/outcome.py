"""How a command ends, for people and for scripts: exit codes, one-line errors, ``--json`` output.

Every command returns 0 on success. A model that was built but not accepted by the dynamic stage's own
checks is still a success (exit 0): the command prints one warning line on stderr and records
``accepted: false`` with ``why`` in its JSON output and ``report.json`` (``warn_unaccepted``).
A failure is one line on stderr (``objscan status: no Zenoh router
answers at tcp/127.0.0.1:7447 [no_router]``) and, under ``--json``, one JSON object on stdout
(``{"error": {"code", "message", "detail"}}``), so a script can branch on the code without parsing text.
The full traceback goes to the log at debug level (``objscan --debug ...`` or ``OBJSCAN_LOG_LEVEL=debug``).
"""

from __future__ import annotations

import json
import logging
import sys
from typing import Any

from common.errors import ObjscanError

log = logging.getLogger("objscan.cli")

OK = 0
FAILED = 1  # the job ran and did not succeed (scan failed, replay differs, an unexpected error)
USAGE = 2  # bad arguments or input (argparse uses 2 as well)
NO_ROUTER = 3  # the Zenoh network could not be joined
NO_SERVICE = 4  # joined, but no service answered
INTERRUPTED = 130

EXIT_BY_CODE = {
    "no_router": NO_ROUTER,
    "unavailable": NO_SERVICE, "timeout": NO_SERVICE, "no_services": NO_SERVICE,
    "invalid_request": USAGE, "bad_message": USAGE, "bad_config": USAGE,
}


def exit_code(exc: BaseException) -> int:
    """The process exit code for an error that ended a command."""
    if isinstance(exc, ObjscanError):
        return EXIT_BY_CODE.get(exc.code, FAILED)
    return FAILED


def error_payload(exc: BaseException) -> dict[str, Any]:
    """``{"code", "message", "detail"}`` of any error (an unexpected one gets code ``internal``)."""
    if isinstance(exc, ObjscanError):
        return {"code": exc.code, "message": exc.message, "detail": exc.detail}
    return {"code": "internal", "message": f"{type(exc).__name__}: {exc}", "detail": {}}


def one_line(text: str, limit: int = 300) -> str:
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def report_error(command: str, exc: BaseException, *, as_json: bool) -> int:
    """Say what went wrong on one line (and as JSON when asked); return the exit code."""
    err = error_payload(exc)
    log.debug("objscan %s failed", command, exc_info=exc)
    hint = "" if log.isEnabledFor(logging.DEBUG) else " (run with --debug for the traceback)" \
        if err["code"] == "internal" else ""
    print(one_line(f"objscan {command}: {err['message']} [{err['code']}]{hint}"), file=sys.stderr)
    if as_json:
        print(json.dumps({"error": err}, default=str))
    return exit_code(exc)


def warn_unaccepted(command: str, result: dict[str, Any]) -> bool:
    """One line on stderr when ``result`` holds a model that was built but not accepted; True if so.

    Why a warning and not a failure: the model is written and may still be useful to a person, but a script
    must not take it as good; ``accepted`` in the JSON output and in ``report.json`` says the same.
    """
    if result.get("accepted") is not False:
        return False
    why = result.get("why") or "see report.json"
    print(one_line(f"objscan {command}: WARNING: model built but NOT accepted: {why}"), file=sys.stderr)
    return True


def print_json(data: Any) -> None:
    """One JSON document on stdout (numpy scalars and paths as plain values)."""
    print(json.dumps(data, default=_plain))


def _plain(v: Any) -> Any:
    if hasattr(v, "item"):
        return v.item()
    if hasattr(v, "tolist"):
        return v.tolist()
    return str(v)

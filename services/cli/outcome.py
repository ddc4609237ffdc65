"""How a command ends, for people and for scripts: exit codes, one-line errors, ``--json`` output.

Exit codes: 0 ok, 1 failed (the job ran and did not succeed), 2 bad usage or input (a missing path, a bad
value: ``INPUT_CODES``), 3 no Zenoh router, 4 no service answered, 130 interrupted.

Every command returns 0 on success. A model that was built but not accepted by the dynamic stage's own
checks is still a success (exit 0): the command prints one warning line on stderr and records
``accepted: false`` with ``why`` in its JSON output and ``report.json`` (``warn_unaccepted``).
A failure is one line on stderr (``objscan status: no Zenoh router
answers at tcp/127.0.0.1:7447 [no_router]``) and, under ``--json``, one JSON object on stdout
(``{"error": {"code", "message", "detail"}}``), so a script can branch on the code without parsing text.
The full traceback goes to the log at debug level (``objscan --debug ...`` or ``OBJSCAN_LOG_LEVEL=debug``).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Any, NoReturn

from common.errors import InvalidRequest, ObjscanError

log = logging.getLogger("objscan.cli")

OK = 0
FAILED = 1  # the job ran and did not succeed (scan failed, replay differs, an unexpected error)
USAGE = 2  # bad arguments or input (argparse uses 2 as well)
NO_ROUTER = 3  # the Zenoh network could not be joined
NO_SERVICE = 4  # joined, but no service answered
INTERRUPTED = 130

INPUT_CODES = frozenset({
    "invalid_request", "bad_message", "bad_config", "bad_usage", "path_not_found", "invalid_config",
    "bad_session", "bad_recording", "bad_source", "out_not_empty", "object_not_found", "bad_mesh", "bad_argument",
    "model_not_found", "ambiguous_id", "not_a_library", "bad_network_config", "bad_value", "too_many_frames",
    "no_frames", "bad_robot_config",
})
"""Error codes that mean the command was given something it cannot use (a missing path, a bad value): exit 2."""

EXIT_BY_CODE = {
    "no_router": NO_ROUTER,
    "unavailable": NO_SERVICE, "timeout": NO_SERVICE, "no_services": NO_SERVICE,
    **{code: USAGE for code in INPUT_CODES},
}


class BadUsage(InvalidRequest):
    """The command line asks for something the command cannot do (a flag combination, a value out of range)."""

    code = "bad_usage"


class PathNotFound(InvalidRequest):
    """A path the command reads does not exist (bad input: exit 2, before any work starts)."""

    code = "path_not_found"


def require_path(path: str | Path, what: str) -> Path:
    """``path`` when it exists, else ``PathNotFound`` naming ``what`` it should have been."""
    p = Path(path).expanduser()
    if not p.exists():
        raise PathNotFound(f"{what} {path} does not exist", detail={"path": str(path)})
    return p


class CliParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are the CLI's one line too: ``objscan scan: argument --views:
    invalid int value: 'many' [bad_usage]`` on stderr, exit 2 (argparse's own voice is a usage block + a line)."""

    def error(self, message: str) -> NoReturn:
        print(one_line(f"{self.prog}: {message} [bad_usage]"), file=sys.stderr)
        raise SystemExit(USAGE)


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
    print(error_line(command, f"{err['message']}{hint}", err["code"]), file=sys.stderr)
    if as_json:
        print(json.dumps({"error": err}, default=str))
    return exit_code(exc)


def error_line(command: str, message: str, code: str, limit: int = 1000) -> str:
    """``objscan <command>: <message> [<code>]`` on one line; a long message is cut, never the code."""
    tail = f" [{code}]"
    return one_line(f"objscan {command}: {message}", limit - len(tail)) + tail


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

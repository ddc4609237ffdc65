"""``objscan``: one command for every job — run the cell, inspect it, scan, reconstruct, benchmark.

Each sub-command lives in its own module with a ``register(subparsers)`` function; this file only
assembles them and decides how a command ends (``services/cli/outcome.py``: exit codes, one-line
errors, tracebacks only at debug level), so adding a command never touches the others. A command reports a
failure by raising (an ``ObjscanError`` with its code); it never prints an error itself. Results printed
under ``--json`` use ``dest="json_output"`` so a failure is a JSON document there too.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from common.log import setup_logging
from common.version import objscan_version
from services.cli import outcome

COMMANDS = [
    "services.cli.cmd_up",
    "services.cli.cmd_status",
    "services.cli.cmd_down",
    "services.cli.cmd_call",
    "services.cli.cmd_bench",
    "services.cli.cmd_scan",
    "services.cli.cmd_capture",
    "services.cli.cmd_reconstruct",
    "services.cli.cmd_export",
    "services.cli.cmd_import",
    "services.cli.cmd_models",
    "services.cli.cmd_report",
    "services.cli.cmd_replay",
    "services.cli.cmd_certs",
    "services.cli.cmd_devices",
    "services.cli.cmd_calibrate",
    "services.cli.cmd_ros2_bag",
]


def command_module(argv: list[str]) -> str | None:
    """The module of the command ``argv`` names (its first word that is not an option), or None when it names
    none of ``COMMANDS`` (then every command is registered, so help and "invalid choice" list them all).

    Why: each command module imports what its command needs (Zenoh, Open3D, OpenCV, the exporter, ...); a
    process that reconstructs a session should not pay the start-up of calibration or export. Top-level options
    take no values, so the first other word is the command."""
    word = next((a for a in argv if not a.startswith("-")), None)
    if word is None:
        return None
    name = f"services.cli.cmd_{word.replace('-', '_')}"
    return name if name in COMMANDS else None


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``objscan`` parser; with ``argv`` naming a command, only that command's module is imported."""
    parser = outcome.CliParser(
        prog="objscan",
        description="Autonomous object model acquisition with a robot arm and a wrist RGB-D camera.",
        epilog="Run 'objscan COMMAND --help' for a command's options. Exit codes: 0 ok, 1 failed, 2 bad "
               "arguments, 3 no Zenoh router, 4 no service answered, 130 interrupted. Docs: README.md, docs/.",
    )
    parser.add_argument("--version", action="version", version=f"objscan {objscan_version()}")
    parser.add_argument("--debug", action="store_true",
                        help="log at debug level, with full tracebacks (or set OBJSCAN_LOG_LEVEL=debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    only = None if argv is None else command_module(argv)
    for name in COMMANDS if only is None else [only]:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    level = "DEBUG" if args.debug else os.environ.get("OBJSCAN_LOG_LEVEL", "WARNING")
    setup_logging("cli", str(os.getpid()), level)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"objscan {args.command}: interrupted [interrupted]", file=sys.stderr)
        return outcome.INTERRUPTED
    except Exception as exc:  # every failure ends as one line + an exit code; the traceback at debug level
        return outcome.report_error(args.command, exc, as_json=bool(getattr(args, "json_output", False)))


if __name__ == "__main__":
    sys.exit(main())

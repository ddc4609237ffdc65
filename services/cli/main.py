"""``objscan``: one command for every job — run the cell, inspect it, scan, reconstruct, benchmark.

Each sub-command lives in its own module with a ``register(subparsers)`` function; this file only
assembles them, so adding a command never touches the others.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = [
    "services.cli.cmd_up",
    "services.cli.cmd_status",
    "services.cli.cmd_call",
    "services.cli.cmd_bench",
    "services.cli.cmd_scan",
    "services.cli.cmd_capture",
    "services.cli.cmd_reconstruct",
    "services.cli.cmd_import",
    "services.cli.cmd_models",
    "services.cli.cmd_report",
    "services.cli.cmd_replay",
    "services.cli.cmd_certs",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="objscan",
        description="Autonomous object model acquisition with a robot arm and a wrist RGB-D camera.",
        epilog="Run 'objscan COMMAND --help' for a command's options. Docs: README.md and docs/.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

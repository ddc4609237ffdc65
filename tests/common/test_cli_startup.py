"""The CLI imports only the command it runs: ``objscan reconstruct`` does not pay for calibration, export or
the physics twin's start-up, and a command it does not know still lists every command."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from services.cli.main import COMMANDS, command_module

pytestmark = pytest.mark.timeout(120)

# modules only other commands need (hand-eye calibration, the exporter and the twin's physics)
OTHER_COMMANDS_MODULES = ("services.calibration.procedure", "services.export", "mujoco", "cv2")


def _modules_after(argv: list[str], watched: tuple[str, ...] = OTHER_COMMANDS_MODULES) -> tuple[int, list[str]]:
    """(exit code, the ``watched`` modules imported) when ``objscan ARGV`` runs in a fresh interpreter."""
    code = (
        "import json, sys\n"
        "from services.cli.main import main\n"
        "try:\n"
        f"    rc = main({argv!r})\n"
        "except SystemExit as exc:\n"
        "    rc = exc.code\n"
        f"print(json.dumps([rc, sorted(m for m in sys.modules if m in {watched!r})]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=100)
    rc, modules = json.loads(proc.stdout.strip().splitlines()[-1])
    return rc, modules


def test_reconstruct_help_imports_no_other_command():
    rc, modules = _modules_after(["reconstruct", "--help"])
    assert rc == 0
    assert modules == []


def test_reconstruct_imports_neither_the_scan_command_nor_zenoh():
    """Reconstructing a session talks to no cell: the scan command's module (and, through it, Zenoh, the cell
    launcher and the acquisition config) is not imported for its console."""
    rc, modules = _modules_after(["reconstruct", "--help"], ("services.cli.cmd_scan", "zenoh", "common.client"))
    assert rc == 0
    assert modules == []


def test_the_command_is_the_first_word_that_is_not_an_option():
    assert command_module(["--debug", "reconstruct", "s", "--out", "o"]) == "services.cli.cmd_reconstruct"
    assert command_module(["ros2-bag", "--help"]) == "services.cli.cmd_ros2_bag"
    assert command_module(["--version"]) is None
    assert command_module(["no-such-command"]) is None
    assert all(name.startswith("services.cli.cmd_") for name in COMMANDS)


def test_an_unknown_command_lists_every_command():
    proc = subprocess.run([sys.executable, "-m", "services.cli", "no-such-command"], capture_output=True,
                          text=True, timeout=100)
    assert proc.returncode == 2
    for name in COMMANDS:
        word = name.removeprefix("services.cli.cmd_").replace("_", "-")
        assert word in proc.stderr

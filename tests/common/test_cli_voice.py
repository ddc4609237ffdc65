"""One CLI voice: every command's failure is one stderr line ``objscan <command>: <message> [<code>]`` with the
exit codes of ``services/cli/outcome.py``, and every flag of every command says what it does."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from services.cli import outcome
from services.cli.main import build_parser

REPO = Path(__file__).resolve().parents[2]
MISSING = "/nonexistent/objscan-missing"
# no command when the command's own name was the bad usage
LINE = re.compile(r"objscan(?: (?P<command>[a-z-]+))?: (?P<message>.+) \[(?P<code>[a-z_]+)\]")


def objscan(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "COLUMNS": "200", "PYTHONPATH": str(REPO),
           "OBJSCAN_STATE_DIR": str(cwd / "state")}
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd, env=env)


# every command that reads a path, with that path missing (the rest of its arguments valid)
MISSING_PATH = {
    "report": ["report", MISSING],
    "reconstruct": ["reconstruct", MISSING, "--out", "out"],
    "reconstruct-gt": ["reconstruct", ".", "--out", "out", "--gt", MISSING + ".ply"],
    "import": ["import", MISSING, "--out", "out"],
    "replay": ["replay", MISSING, "--out", "out"],
    "replay-registration": ["replay", MISSING, "--out", "out", "--only", "registration"],
    "replay-view": ["replay", MISSING, "--rerun-save", "out.rrd"],
    "models-find": ["models", "--library", "lib", "find", MISSING + ".ply"],
    "scan-resume": ["scan", "--resume", MISSING],
    "scan-config": ["scan", "--config", MISSING + ".yaml"],
    "scan-object": ["scan", "--object", MISSING + "/mug.glb"],
    "capture-session": ["capture", "--backend", "replay", "--session", MISSING, "--out", "out"],
    "devices-robot-config": ["devices", "--emulate-bus", "--robot-config", MISSING + ".yaml"],
    "up-robot-config": ["up", "--robot-config", MISSING + ".yaml"],
}


@pytest.mark.parametrize("case", sorted(MISSING_PATH))
def test_a_missing_path_is_one_stderr_line_and_exit_2(case, tmp_path):
    res = objscan(*MISSING_PATH[case], cwd=tmp_path)
    lines = res.stderr.splitlines()
    assert res.returncode == outcome.USAGE == 2, res
    assert len(lines) == 1, res.stderr
    m = LINE.fullmatch(lines[0])
    assert m is not None, lines[0]
    assert m["command"] == MISSING_PATH[case][0]
    assert m["code"] in ("path_not_found", "object_not_found") and MISSING in m["message"], lines[0]
    assert res.stdout == "", res.stdout
    assert not (tmp_path / "out").exists() and not (tmp_path / "lib").exists()  # nothing was started or written


@pytest.mark.parametrize("case", ["report", "reconstruct", "import", "replay", "scan-resume", "models-find"])
def test_a_missing_path_under_json_is_also_one_json_document(case, tmp_path):
    argv = list(MISSING_PATH[case])
    argv.insert(argv.index("--library") if "--library" in argv else 1, "--json")
    res = objscan(*argv, cwd=tmp_path)
    assert res.returncode == 2 and len(res.stderr.splitlines()) == 1, res
    doc = json.loads(res.stdout)
    assert doc["error"]["code"] == "path_not_found" and MISSING in doc["error"]["message"]


@pytest.mark.parametrize("argv, code", [
    (["scan", "--views", "many"], "bad_usage"),
    (["scan", "--up-axis", "w"], "bad_usage"),
    (["scan", "--workspace-center", "0.6"], "bad_usage"),
    (["scan", "--workspace-center", "1.5,0.0"], "invalid_config"),
    (["scan", "--workspace-center", "0.05,0.0"], "invalid_config"),
    (["scan", "--turn-deg", "0"], "invalid_config"),
    (["scan", "--turn-deg", "200"], "invalid_config"),
    (["scan", "--scale", "-1"], "invalid_config"),
    (["nosuchcommand"], "bad_usage"),
])
def test_bad_values_are_one_line_exit_2_before_anything_starts(argv, code, tmp_path):
    res = objscan(*argv, cwd=tmp_path)
    lines = res.stderr.splitlines()
    assert res.returncode == 2 and len(lines) == 1 and res.stdout == "", res
    m = LINE.fullmatch(lines[0])
    assert m is not None and m["code"] == code, lines[0]


def _flag_actions(parser: argparse.ArgumentParser, path: str):
    """(where, action) for every argument of ``parser`` and of every sub-command below it."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield f"{path} {name}", helps.get(name)  # the sub-command's own one-line help
                yield from _flag_actions(sub, f"{path} {name}")
        elif not isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            yield f"{path} {'/'.join(action.option_strings) or action.dest}", action


def test_every_flag_of_every_command_has_help():
    missing = []
    for where, action in _flag_actions(build_parser(), "objscan"):
        text = action if isinstance(action, str) or action is None else action.help
        if not text or text == argparse.SUPPRESS or not str(text).strip():
            missing.append(where)
    assert not missing, f"no help text: {missing}"


def test_the_walk_sees_every_command_and_subcommand():
    """The help test covers what a user can type: every command, the nested actions, their flags."""
    seen = {where for where, _ in _flag_actions(build_parser(), "objscan")}
    for expected in ("objscan scan --scale", "objscan scan --config", "objscan models find --top",
                     "objscan calibrate hand-eye --robot", "objscan status --json", "objscan report session"):
        assert expected in seen, expected

"""How the CLI ends, as a script sees it: ``--version``, ``--json`` documents, one-line errors, exit codes."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

from common.launcher import ProcessSpec
from common.zenoh_config import free_tcp_port
from services.cli import outcome
from services.cli.cmd_scan import _summary, _summary_json

REPO = Path(__file__).resolve().parents[2]


def objscan(*args: str, timeout: float = 60, **env: str) -> subprocess.CompletedProcess[str]:
    base = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "COLUMNS": "200", "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env={**base, **env})


def test_version_matches_the_project_metadata():
    res = objscan("--version")
    version = re.search(r'(?m)^version\s*=\s*"([^"]+)"', (REPO / "pyproject.toml").read_text()).group(1)
    assert res.returncode == 0 and res.stdout.strip() == f"objscan {version}", res


def test_status_json_without_a_router_fails_fast_with_one_line():
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"  # nobody listens here
    t0 = time.monotonic()
    res = objscan("status", "--json", "--connect", endpoint, timeout=30)
    elapsed = time.monotonic() - t0
    assert elapsed < 15, elapsed
    assert res.returncode == outcome.NO_ROUTER == 3, res
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("objscan status: no Zenoh router answers at " + endpoint)
    doc = json.loads(res.stdout)  # exactly one JSON document on stdout
    assert doc["error"]["code"] == "no_router" and endpoint in doc["error"]["message"]


def test_debug_shows_the_full_traceback():
    res = objscan("--debug", "status", "--connect", f"tcp/127.0.0.1:{free_tcp_port()}", timeout=30)
    assert res.returncode == 3
    assert "Traceback (most recent call last)" in res.stderr and "RouterUnreachable" in res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("objscan status: no Zenoh router")


def test_status_json_lists_live_services_and_no_service_is_exit_4(service_group):
    ep = service_group.endpoint
    res = objscan("status", "--json", "--connect", ep)
    assert res.returncode == outcome.NO_SERVICE == 4, res
    assert json.loads(res.stdout)["error"]["code"] == "no_services"
    assert res.stderr.count("\n") == 1
    service_group.launch([ProcessSpec("tests.support.echo_service", ["--instance", "alpha"], service="echo",
                                      name="alpha")])
    res = objscan("status", "--json", "--connect", ep)
    assert res.returncode == 0, res.stderr
    rows = json.loads(res.stdout)["services"]
    alpha = [r for r in rows if r["instance"] == "alpha"]
    assert len(alpha) == 1 and alpha[0]["service"] == "echo" and alpha[0]["status"] == "ok"
    assert alpha[0]["uptime_s"] >= 0 and isinstance(alpha[0]["info"], dict)


def test_bad_arguments_exit_2():
    res = objscan("scan", "--views", "many")
    assert res.returncode == 2 and "invalid int value" in res.stderr


def test_scan_json_summary_done_and_failed(capsys, tmp_path):
    done = {"status": "done", "state": "done", "model": str(tmp_path / "model.ply"), "views": 2, "views_done": 2,
            "accuracy": {"chamfer_mm": 1.2}}
    assert _summary_json(done, tmp_path, 12.34) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["status"] == "done" and doc["accuracy"] == {"chamfer_mm": 1.2} and doc["seconds"] == 12.3
    assert "error" not in doc and doc["session"] == str(tmp_path)
    failed = {"status": "failed", "state": "failed",
              "last_error": {"code": "no_grasp", "message": "none left", "state": "grasp"}}
    assert _summary_json(failed, tmp_path, 1.0) == 1
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["status"] == "failed" and doc["error"]["code"] == "no_grasp"
    assert captured.err.splitlines() == ["objscan scan: failed in state grasp: none left [no_grasp]"]
    assert _summary(failed, tmp_path, 1.0) == 1  # without --json: the line alone, stdout empty
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.splitlines() == [
        f"objscan scan: failed in state grasp: none left; resume with: objscan scan --resume {tmp_path} [no_grasp]"]


def test_exit_codes_follow_error_codes():
    from common.errors import InvalidRequest, RequestTimeout, RouterUnreachable

    assert outcome.exit_code(RouterUnreachable("x")) == 3
    assert outcome.exit_code(RequestTimeout("x")) == 4
    assert outcome.exit_code(InvalidRequest("x")) == 2
    assert outcome.exit_code(ValueError("x")) == 1

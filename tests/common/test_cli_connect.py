"""Every CLI command that talks to a cell honours ``--connect`` (and the TLS variables through it), and a
remote ``objscan scan`` sends session paths relative to the orchestrator's sessions root, so sessions
land inside the sessions volume of a compose cell."""

from __future__ import annotations

import subprocess
import sys

import pytest

from common import keys
from common.client import request_sync
from common.launcher import ProcessSpec
from common.messages import Request
from services.cli.cells import session_name
from services.cli.main import build_parser

pytestmark = pytest.mark.timeout(180)
CELL_COMMANDS = ["status", "call", "scan", "capture"]


def test_session_names_sent_to_a_remote_cell():
    assert session_name("milk-001") == "milk-001"
    assert session_name("sessions/milk-001") == "milk-001"  # the CLI's default folder maps onto the root
    assert session_name("lab/a/b") == "lab/a/b"
    for bad in ("/home/me/sessions/x", "../x", "a/../../b", ""):
        with pytest.raises(ValueError):
            session_name(bad)


@pytest.mark.parametrize("argv", [["status"], ["call", "objscan/x"], ["scan"], ["capture", "--out", "x"], ["up"],
                                  ["calibrate", "hand-eye"]])
def test_cell_commands_take_connect(argv, monkeypatch):
    monkeypatch.delenv("OBJSCAN_ZENOH_CONNECT", raising=False)
    args = build_parser().parse_args([*argv, "--connect", "tls/box:7447"])
    assert args.connect == "tls/box:7447"
    monkeypatch.setenv("OBJSCAN_ZENOH_CONNECT", "tcp/10.0.0.5:7447")
    assert build_parser().parse_args(argv).connect == "tcp/10.0.0.5:7447"  # the environment is the default


def test_remote_orchestrator_puts_relative_sessions_under_its_root(service_group, tmp_path):
    root = tmp_path / "volume" / "sessions"
    service_group.launch([ProcessSpec("services.orchestrator", ["--sessions", str(root), "--library", ""],
                                      service="orchestrator")])
    reply = request_sync(service_group.session, keys.orchestrator(keys.DEFAULT_ROBOT, "run"),
                         Request(params={"out": "milk-001", "record": False, "config": {"views": 3}}), timeout=30)
    assert reply.info["session"] == str((root / "milk-001").resolve())


def test_scan_connect_without_a_cell_says_what_is_missing(service_group):
    proc = subprocess.run([sys.executable, "-m", "services.cli", "scan", "--connect", service_group.endpoint,
                           "--out", "x"], capture_output=True, text=True, timeout=60,
                          env={"PATH": "/usr/bin:/bin", "COLUMNS": "200", "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 4  # joined, but no service answered (services/cli/outcome.py)
    assert "no orchestrator service" in proc.stderr, proc.stdout + proc.stderr


def test_scan_connect_refuses_a_client_path(service_group):
    proc = subprocess.run([sys.executable, "-m", "services.cli", "scan", "--connect", service_group.endpoint,
                           "--out", "/home/me/x"], capture_output=True, text=True, timeout=60,
                          env={"PATH": "/usr/bin:/bin", "COLUMNS": "200", "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 2 and "relative to the cell's sessions root" in proc.stderr, proc.stdout + proc.stderr


def test_up_connect_joins_a_running_router(service_group, tmp_path):
    """``objscan up --connect`` starts services on an existing network and no router of its own."""
    import signal
    import time

    from common.client import live_services

    proc = subprocess.Popen([sys.executable, "-m", "services.cli", "up", "--only", "grasp", "--connect",
                             service_group.endpoint, "--log-dir", str(tmp_path / "up-logs")],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={"PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1"}, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if "grasp" in {s for s, _ in live_services(service_group.session, timeout=1.0)}:
                break
            assert proc.poll() is None, proc.stdout.read()
        else:
            pytest.fail("grasp never joined the router")
        assert not (tmp_path / "up-logs" / "router.log").exists()
    finally:
        proc.send_signal(signal.SIGINT)
        out = proc.communicate(timeout=60)[0]
    assert f"joining {service_group.endpoint}" in out


def test_a_missing_tls_file_is_a_clear_error(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "COLUMNS": "200", "OMP_NUM_THREADS": "1",
           "OBJSCAN_ZENOH_TLS_CA": str(tmp_path / "nope" / "ca.pem")}
    proc = subprocess.run([sys.executable, "-m", "services.cli", "scan", "--connect", "tls/127.0.0.1:9", "--out",
                           "x"], capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2 and "ca.pem does not exist" in proc.stderr, proc.stdout + proc.stderr  # bad input
    assert len(proc.stderr.strip().splitlines()) == 1  # one line, no traceback

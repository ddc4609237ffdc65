"""The objscan CLI against real service processes: status, call, and a killed service vanishing."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time

import pytest

from common.launcher import ProcessSpec


def objscan(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin",
                                                "COLUMNS": "200"})


def test_help_lists_commands():
    out = objscan("--help").stdout
    for cmd in ("up", "status", "call", "bench"):
        assert cmd in out


@pytest.fixture
def two_echoes(service_group):
    service_group.launch([ProcessSpec("tests.support.echo_service", ["--instance", "alpha"], service="echo",
                                      name="alpha"),
                          ProcessSpec("tests.support.echo_service", ["--instance", "beta"], service="echo",
                                      name="beta")])
    return service_group


def test_status_lists_services_and_a_killed_one_vanishes(two_echoes):
    ep = two_echoes.endpoint
    out = objscan("status", "--connect", ep).stdout
    assert "alpha" in out and "beta" in out and "ok" in out
    two_echoes.kill("beta")
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        out = objscan("status", "--connect", ep).stdout
        if "beta" not in out:
            break
        time.sleep(0.5)
    assert "alpha" in out and "beta" not in out


def test_call_prints_decoded_reply_and_typed_errors(two_echoes):
    ep = two_echoes.endpoint
    res = objscan("call", "objscan/test/alpha/echo", '{"x": [1, 2, 3]}', "--connect", ep)
    assert res.returncode == 0, res.stderr
    reply = json.loads(res.stdout)
    assert reply["type"] == "Request" and reply["params"]["x"] == [1, 2, 3]
    res = objscan("call", "objscan/test/alpha/crash", "--connect", ep, "--json")
    assert res.returncode == 1 and json.loads(res.stdout)["error"]["code"] == "internal"
    assert len(res.stderr.splitlines()) == 1 and res.stderr.startswith("objscan call: ")
    assert res.stderr.rstrip().endswith("[internal]"), res.stderr
    res = objscan("call", "objscan/test/nobody/echo", "--connect", ep, "--timeout", "2")
    assert res.returncode == 4 and res.stdout == ""
    assert re.fullmatch(r"objscan call: .+ \[(unavailable|timeout)\]\n", res.stderr), res.stderr

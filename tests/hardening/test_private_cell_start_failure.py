"""A private cell whose twin cannot load the scan's object: the scan's one line is the twin's own typed error
(``object_not_found`` and what it knows), exit 2, and nothing of the cell is left running.

Before, the line was ``objscan scan: RuntimeError: sim exited with code 1 before it was live; see .../sim.log
[internal]`` and the reason was only in that log."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from common.zenoh_config import free_tcp_port
from services.private_cell import port_free, read_record
from tests.conftest import REPO


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_twin_that_cannot_load_the_object_is_the_scans_one_line(tmp_path):
    port = free_tcp_port()  # a cell of its own, never one another scan on this machine runs
    env = dict(os.environ, OMP_NUM_THREADS="1", OBJSCAN_STATE_DIR=str(tmp_path / "state"))
    res = subprocess.run([sys.executable, "-m", "services.cli.main", "scan", "--object", "no-such-object",
                          "--port", str(port), "--out", str(tmp_path / "session"), "--physics", "geometric",
                          "--no-record", "--cell-grace", "1"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=540)
    lines = res.stderr.splitlines()
    assert res.returncode == 2, res
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("objscan scan: sim could not start: unknown object 'no-such-object'"), lines[0]
    assert lines[0].endswith("[object_not_found]") and "internal" not in lines[0], lines[0]
    assert port_free(port) and read_record(port) is None  # the keeper stopped what it started

"""Hardware in the loop without hardware: a whole acquisition with the *dynamixel* arm backend.

``objscan scan --object milk --views 3 --arm-backend dynamixel --emulate-bus --out DIR``, exactly as a user
types it (on a free router port): the arm service runs the real DYNAMIXEL driver, every servo read and
write going through dynamixel-sdk as Protocol 2.0 packets on a pty, against an emulated PAPRAS bus of
DYNAMIXEL-P servos whose present positions drive the twin that the camera renders.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import open3d as o3d
import pytest

from common.zenoh_config import free_tcp_port

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_three_view_acquisition_on_the_emulated_p_series_bus(tmp_path):
    out = tmp_path / "session"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-m", "services.cli", "scan", "--object", "milk", "--views", "3", "--arm-backend",
         "dynamixel", "--emulate-bus", "--out", str(out), "--port", str(free_tcp_port())],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=1400)
    arm_log = (out / "logs" / "arm.log").read_text()
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:] + arm_log[-3000:]
    model = o3d.io.read_point_cloud(str(out / "model.ply"))
    assert len(model.points) > 3000 and model.has_colors()
    # the arm really was the DYNAMIXEL driver on the emulated P-series bus, and the bus drove the twin
    assert "dynamixel driver on an emulated bus driving the twin" in arm_log
    for model_name in ("PH54-200-S500-R", "PH54-100-S500-R", "PH42-020-S300-R", "RH-P12-RN(A)"):
        assert model_name in arm_log
    closed = re.search(r"emulated bus closed.*sync_writes=(\d+).*sync_reads=(\d+).*twin_updates=(\d+)", arm_log)
    assert closed, arm_log[-2000:]
    writes, reads, updates = (int(g) for g in closed.groups())
    assert writes > 500 and reads >= writes and updates > 50

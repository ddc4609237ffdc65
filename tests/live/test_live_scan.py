"""A real short scan watched live: ``objscan scan --rerun-save`` through every service process, then the same
session replayed into a second ``.rrd`` with ``objscan replay SESSION --rerun-save``. Both files are read back
with the Rerun SDK. Slow: a whole 3-view acquisition (the fewest a model accepts; ~4-6 minutes on a shared 2-core box).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from common.zenoh_config import free_tcp_port
from tests.conftest import shared_data
from tests.live.rrd_entities import rrd_entities

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


def _objscan(*args: str, timeout: float) -> subprocess.CompletedProcess[str]:
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "PYTHONPATH": str(REPO), "COLUMNS": "200"}
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO, env=env)


def _check_scene(ents: dict[str, dict[str, int]], views: int) -> None:
    assert ents["/world/camera/image/color"]["Image:buffer"] >= 3 * views  # 3 scan poses per view, + locate
    assert ents["/world/camera/image/depth"]["DepthImage:buffer"] == ents["/world/camera/image/color"]["Image:buffer"]
    assert ents["/world/camera"]["Transform3D:translation"] >= 3 * views
    for k in range(views):
        assert ents[f"/world/views/{k:02d}/object"]["Points3D:positions"] >= 1
    assert ents["/world/grasps/candidates"]["Arrows3D:vectors"] >= 1
    assert ents["/world/grasps/chosen"]["Transform3D:translation"] >= 1
    assert ents["/world/model"]["Points3D:positions"] == 1
    assert ents["/world/model_preview"]["Points3D:positions"] >= views  # grows with every registered view
    assert ents["/world/arm/joints/robot1\\/joint2"]["Transform3D:child_frame"] > 10  # the arm moved


def test_scan_streams_to_rrd_and_the_recording_replays_into_the_same_scene(tmp_path):
    shared_data("hope", "milk")
    live, replayed, session = tmp_path / "live.rrd", tmp_path / "replayed.rrd", tmp_path / "session"
    res = _objscan("scan", "--object", "milk", "--views", "3", "--seed", "1", "--out", str(session),
                   "--port", str(free_tcp_port()), "--library", str(tmp_path / "models"), "--json",
                   "--rerun-save", str(live), timeout=1200)
    doc = json.loads(res.stdout)  # --json: stdout is one JSON document
    assert res.returncode == 0 and doc["status"] == "done", (doc, res.stderr[-3000:])
    assert doc["views_done"] == 3 and Path(doc["model"]).is_file()
    _check_scene(rrd_entities(live), 3)
    res = _objscan("replay", str(session), "--rerun-save", str(replayed), timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    _check_scene(rrd_entities(replayed), 3)

"""``arm/scene`` changing the collision model while a motion is checked in another thread.

Why: the check read Pinocchio's geometry data while the scene rebuilt it; the process died of heap
corruption (SIGABRT) within a second. Now one lock covers scene changes and checks, and a trajectory is
checked against one scene throughout (its answer is one of the two scenes' answers)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


def test_checks_and_scene_changes_in_parallel_threads():
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(repo)}
    out = subprocess.run([sys.executable, "-m", "tests.hardening.collision_race", "2.0"], cwd=repo, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"the checking process died ({out.returncode}): {out.stderr[-500:]}"
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["errors"] == [] and result["inconsistent"] == 0, result
    assert result["checks"] > 0 and result["scene_changes"] > 0
    assert len(result["answers"]) == 2  # the box really changes the answer: the race is a real one

"""A test run given a wall-clock deadline (``OBJSCAN_TEST_DEADLINE``, CI's slow cases) starts no test after it
and reports each one left out as skipped, so CI ends on time with a readable list instead of being killed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
QUICK = "tests/orchestrator/test_journal.py::test_an_old_journal_loads_field_by_field"


def _run(deadline: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OBJSCAN_TEST_DEADLINE"}
    if deadline is not None:
        env["OBJSCAN_TEST_DEADLINE"] = deadline
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", QUICK], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=120)
    return proc.stdout


def test_a_spent_budget_skips_and_names_the_test_and_a_running_budget_does_not():
    spent = _run("1")
    assert "1 skipped" in spent and "time budget" in spent, spent[-500:]
    assert "1 passed" in _run("99999999999"), "a budget not yet spent must not skip"

"""Shared fixtures: paths to the shared real data and a loopback Zenoh network of real processes."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()


def shared_data(*parts: str) -> Path:
    """Path into ../shared/data; skips the test when the shared data is not beside the checkout."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared data not found: {path}")
    return path


@pytest.fixture
def service_group(tmp_path):
    """A Zenoh router on a free loopback port; tests add service processes with ``launch``."""
    from common.launcher import ServiceGroup

    group = ServiceGroup(log_dir=tmp_path / "logs")
    group.start_router()
    try:
        yield group
    finally:
        group.stop_all()


DEADLINE_ENV = "OBJSCAN_TEST_DEADLINE"  # seconds since the epoch after which no further test starts


def pytest_runtest_setup(item: pytest.Item) -> None:
    """A run with a wall-clock budget (CI's slow cases) skips, and names, the tests that would start after it:
    a run that stops on time reports what it left out instead of being killed with nothing reported."""
    deadline = os.environ.get(DEADLINE_ENV)
    if deadline and float(deadline) < time.time():
        pytest.skip(f"the run's time budget ({DEADLINE_ENV}) is spent")

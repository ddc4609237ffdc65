"""Hostile payloads must not hold the e-stop.

Why: every payload was decoded on the service's event loop with no budget, so three 5 MB payloads of
tiny msgpack arrays sent to ``arm/state`` kept the arm from answering ``stop`` for 25 s. Now each key has a
byte and element budget checked before (or early in) parsing, large payloads are decoded off the loop and
``stop``/health are never refused by the bound on requests in progress.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from bench.estop import HostileLoad, element_bomb, time_stops, tiny_arrays_bomb
from common import keys
from common.client import request_sync
from common.codec import decode
from common.errors import WireError
from common.launcher import ProcessSpec
from common.messages import Health, Ok
from common.runtime import COMMAND_BUDGET, Budget

ROBOT = keys.DEFAULT_ROBOT


def test_element_budget_refuses_a_bomb_early():
    bomb = tiny_arrays_bomb(5 * 1024 * 1024)
    assert len(bomb) >= 5 * 1024 * 1024
    t0 = time.perf_counter()
    with pytest.raises(WireError) as err:
        decode(bomb, max_elements=COMMAND_BUDGET.max_elements)
    assert err.value.code == "too_many_elements"
    assert time.perf_counter() - t0 < 0.05  # the outer container's length is charged before its items are read
    with pytest.raises(WireError) as err:
        decode(element_bomb(30_000), max_bytes=COMMAND_BUDGET.max_bytes, max_elements=COMMAND_BUDGET.max_elements)
    assert err.value.code == "too_many_elements"
    with pytest.raises(WireError) as err:
        decode(bomb, max_bytes=COMMAND_BUDGET.max_bytes)
    assert err.value.code == "oversize"


def test_budget_validates():
    for bad in ({"max_bytes": 0}, {"max_elements": -1}, {"max_elements": 2.5}, {"max_bytes": 1 << 40}):
        with pytest.raises(ValueError):
            Budget(**bad)


@pytest.fixture
def arm_cell(service_group):
    service_group.launch([ProcessSpec("services.sim", service="sim"),
                          ProcessSpec("services.arm", ["--backend", "sim"], service="arm")], timeout=180)
    return service_group


def test_stop_answers_while_hostile_payloads_arrive(arm_cell):
    s = arm_cell.session
    hostile = HostileLoad(arm_cell)
    try:
        time.sleep(2.0)
        latencies = time_stops(s, ROBOT, 40, timeout_s=10.0)
    finally:
        load = hostile.stop()
    # the strict figure (p99 <= 50 ms) is `objscan bench estop`'s; on a shared 2-core machine at load average 25
    # the arm waits for a CPU (bench max 438 ms there), so the test's bound keeps a margin: before the fix no stop
    # was answered at all within 30 s
    assert float(np.percentile(latencies, 99)) < 1000.0, latencies
    assert all(v < 10_000 for v in latencies)  # every stop answered
    assert load["sent"].get("state_bombs", 0) >= 3
    assert load["answers"]["state_bombs"].get("oversize", 0) >= 3
    assert load["answers"]["element_bomb"].get("too_many_elements", 0) >= 1
    assert isinstance(request_sync(s, keys.health("arm", "*"), timeout=10), Health)
    assert isinstance(request_sync(s, keys.arm(ROBOT, "stop"), timeout=10), Ok)
    assert arm_cell.procs["arm"].poll() is None

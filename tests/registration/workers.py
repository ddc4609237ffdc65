"""Two real registration workers on a test's Zenoh network, and which of them is computing a pair job:
what the killed-worker tests (dynamic and single-pair) share."""

from __future__ import annotations

import time
from collections.abc import Callable

from common import keys
from common.client import live_services, request_sync
from common.errors import ObjscanError
from common.launcher import ProcessSpec
from common.messages import Health

INSTANCES = ("w1", "w2")


def launch_two_workers(group) -> None:  # noqa: ANN001 - a ServiceGroup
    group.launch([ProcessSpec("services.registration", ["--instance", i], service="registration", name=i)
                  for i in INSTANCES], timeout=180)
    deadline = time.monotonic() + 30
    while len([i for s, i in live_services(group.session) if s == "registration"]) < 2:
        assert time.monotonic() < deadline
        time.sleep(0.2)


def _health(group, instance: str) -> Health | None:  # noqa: ANN001
    try:
        return request_sync(group.session, keys.health("registration", instance), timeout=2)
    except ObjscanError:
        return None


def worker_computing_a_pair(group, keep_looking: Callable[[], bool]) -> str | None:  # noqa: ANN001
    """The instance that is computing a pair job and is not the one coordinating, polled while
    ``keep_looking()``; None if none was seen."""
    while keep_looking():
        for inst in INSTANCES:
            h = _health(group, inst)
            if h is not None and h.info.get("coordinating", 0) == 0 and h.info.get("pairs_running", 0) > 0:
                return inst
        time.sleep(0.05)
    return None

"""Dynamic registration spread over real registration worker processes; a killed worker loses no job."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from common import keys
from common.api import DynamicRequest, ModelResult, ViewResult
from common.client import live_services, request_sync
from common.errors import ObjscanError
from common.launcher import ProcessSpec
from common.messages import Health, PointCloud


def _requests(n_views: int = 12) -> DynamicRequest:
    from services.registration.dynamic.synthetic import synthetic_views

    scan = synthetic_views("milk", views=n_views, seed=0)
    views = [ViewResult(view=v.index, cloud=PointCloud(xyz=np.asarray(v.xyz, np.float32),
                                                       rgb=np.asarray(v.rgb, np.uint8),
                                                       normals=None if v.normals is None else
                                                       np.asarray(v.normals, np.float32)),
                        table=v.table, center=np.asarray(v.center, float), height=0.19,
                        scan_poses=np.zeros((0, 4, 4))) for v in scan.views]
    return DynamicRequest(views=views, turns_deg=[v.commanded_turn_deg for v in scan.views])


def _health(group, instance: str) -> Health | None:  # noqa: ANN001
    try:
        return request_sync(group.session, keys.health("registration", instance), timeout=2)
    except ObjscanError:
        return None


@pytest.mark.slow
def test_a_killed_worker_has_its_pair_job_finished_by_another(service_group):
    request = _requests()
    service_group.launch([ProcessSpec("services.registration", ["--instance", "w1"], service="registration",
                                      name="w1"),
                          ProcessSpec("services.registration", ["--instance", "w2"], service="registration",
                                      name="w2")], timeout=180)
    deadline = time.monotonic() + 30
    while len([i for s, i in live_services(service_group.session) if s == "registration"]) < 2:
        assert time.monotonic() < deadline
        time.sleep(0.2)
    result: dict[str, object] = {}

    def run() -> None:
        result["reply"] = request_sync(service_group.session, keys.REGISTRATION_DYNAMIC, request, timeout=900)

    t = threading.Thread(target=run)
    t.start()
    victim = None
    deadline = time.monotonic() + 300
    while victim is None and time.monotonic() < deadline:  # kill the worker that is not coordinating, mid-job
        for inst in ("w1", "w2"):
            h = _health(service_group, inst)
            if h is not None and h.info.get("coordinating", 0) == 0 and h.info.get("pairs_running", 0) > 0:
                victim = inst
        time.sleep(0.05)
    assert victim is not None, "no worker ever took a pair job"
    service_group.kill(victim)
    t.join(900)
    reply = result.get("reply")
    assert isinstance(reply, ModelResult), reply
    workers = reply.figures["workers"]
    assert workers.get("retried", 0) >= 1, workers
    assert len(reply.cloud) > 10_000
    assert reply.figures["loop_closure"]["rotation_deg"] < 3.0

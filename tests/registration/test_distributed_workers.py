"""Dynamic registration spread over real registration worker processes; a killed worker loses no job."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from common import keys
from common.api import DynamicRequest, ModelResult, ViewResult
from common.client import request_sync
from common.messages import PointCloud
from tests.registration.workers import launch_two_workers, worker_computing_a_pair


def _requests(n_views: int = 12) -> DynamicRequest:
    from bench.synthetic import synthetic_views

    scan = synthetic_views("milk", views=n_views, seed=0)
    views = [ViewResult(view=v.index, cloud=PointCloud(xyz=np.asarray(v.xyz, np.float32),
                                                       rgb=np.asarray(v.rgb, np.uint8),
                                                       normals=None if v.normals is None else
                                                       np.asarray(v.normals, np.float32)),
                        # the footprint centre and the height, as the static stage sends them (table: z = 0)
                        table=v.table, center=np.asarray(v.center, float) * [1, 1, 0], height=2 * float(v.center[2]),
                        scan_poses=np.zeros((0, 4, 4))) for v in scan.views]
    return DynamicRequest(views=views, turns_deg=[v.commanded_turn_deg for v in scan.views])


@pytest.mark.slow
def test_a_killed_worker_has_its_pair_job_finished_by_another(service_group):
    request = _requests()
    launch_two_workers(service_group)
    result: dict[str, object] = {}

    def run() -> None:
        result["reply"] = request_sync(service_group.session, keys.REGISTRATION_DYNAMIC, request, timeout=900)

    t = threading.Thread(target=run)
    t.start()
    deadline = time.monotonic() + 300  # kill the worker that is not coordinating, mid-job
    victim = worker_computing_a_pair(service_group, lambda: time.monotonic() < deadline)
    assert victim is not None, "no worker ever took a pair job"
    service_group.kill(victim)
    t.join(900)
    reply = result.get("reply")
    assert isinstance(reply, ModelResult), reply
    workers = reply.figures["workers"]
    assert workers.get("retried", 0) >= 1, workers
    assert len(reply.cloud) > 10_000
    assert reply.figures["loop_closure"]["rotation_deg"] < 3.0

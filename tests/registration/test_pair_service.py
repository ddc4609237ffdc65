"""``objscan/registration/pair`` over Zenoh: a real registration process runs one pair job (the incremental
model's) and answers exactly what the job gives when run here; a killed worker's job is re-run by another."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from common import keys
from common.client import request_sync
from common.launcher import ProcessSpec
from tests.conftest import shared_data
from tests.registration.workers import launch_two_workers, worker_computing_a_pair


def _job():
    shared_data("hope", "milk")
    from bench.synthetic import synthetic_views
    from services.registration.dynamic.model import DynamicConfig, early_pair_job
    from services.registration.dynamic.preprocess import PreprocessConfig

    views = synthetic_views("milk", views=12, profile="hand-turned", seed=3, voxel=0.003).views
    cfg = DynamicConfig(configuration="no_region", preprocess=PreprocessConfig(palette_views=2))
    return early_pair_job(dict(enumerate(views[:3])), 2, cfg)


def test_a_pair_job_sent_to_registration_pair_comes_back_as_computed_here(service_group):
    from services.registration.dynamic.pair import register_pair
    from services.registration.pair_wire import PairResultMessage, pair_job_message, pair_result_from_message

    job = _job()
    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=180)
    reply = request_sync(service_group.session, keys.REGISTRATION_PAIR, pair_job_message(job), timeout=300)
    assert isinstance(reply, PairResultMessage), reply
    there, here = pair_result_from_message(reply), register_pair(job)
    assert (there.source_view, there.target_view, there.index) == (2, 1, 1)
    assert np.allclose(there.T, here.T, atol=1e-9) and abs(there.fitness - here.fitness) < 1e-9
    # a speculative job runs in the background pool (niceness 19, pair_pool.py): the same result
    reply = request_sync(service_group.session, keys.REGISTRATION_PAIR, pair_job_message(job, background=True),
                         timeout=300)
    assert np.array_equal(pair_result_from_message(reply).T, there.T)


def test_background_pair_workers_run_at_the_lowest_cpu_priority():
    import asyncio

    from services.registration.pair_pool import PairPool

    async def go():
        pools = PairPool(1), PairPool(1, nice=19)
        try:
            return [await p.niceness() for p in pools]
        finally:
            for p in pools:
                p.close()

    normal, background = asyncio.run(go())
    assert background == min(19, normal + 19) and background > normal


@pytest.mark.slow
def test_a_pair_job_whose_worker_is_killed_is_finished_by_another(service_group):
    from services.registration.pair_wire import PairResultMessage, pair_job_message

    msg = pair_job_message(_job())
    launch_two_workers(service_group)
    for _attempt in range(4):  # the job may land on the coordinating instance itself: then ask again
        result: dict[str, object] = {}
        t = threading.Thread(target=lambda out=result: out.update(
            reply=request_sync(service_group.session, keys.REGISTRATION_PAIR, msg, timeout=600)))
        t.start()
        victim = worker_computing_a_pair(service_group, t.is_alive)  # running the job, not coordinating
        if victim is not None:
            service_group.kill(victim)
        t.join(600)
        assert isinstance(result.get("reply"), PairResultMessage), result
        if victim is not None:
            return
    pytest.fail("the pair job never ran on the non-coordinating worker")

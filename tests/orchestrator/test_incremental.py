"""The incremental model in the orchestrator: pair jobs go out as views are registered, the state machine does
not wait on them, finished ones are stored atomically and survive a restart, and the final dynamic request
carries them (services/orchestrator/incremental.py)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from common.api import ModelResult, ViewResult
from common.messages import PointCloud
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.incremental import PAIRS_DIR, IncrementalModel
from services.orchestrator.machine import Acquisition, State
from services.session_store import SessionStore
from tests.conftest import shared_data

VIEWS = 4


@pytest.fixture(scope="module")
def view_results():
    shared_data("hope", "milk")
    from bench.synthetic import synthetic_views

    scan = synthetic_views("milk", views=12, profile="hand-turned", seed=3, voxel=0.003)
    out = []
    for v in scan.views[:VIEWS]:
        cloud = PointCloud(xyz=np.asarray(v.xyz, np.float32), rgb=np.asarray(v.rgb, np.uint8),
                           normals=np.asarray(v.normals, np.float32))
        out.append(ViewResult(view=v.index, cloud=cloud, table=v.table, center=np.asarray(v.center, float),
                              height=0.19, scan_poses=np.zeros((0, 4, 4))))
    return out, [v.commanded_turn_deg for v in scan.views[:VIEWS]]


class PairCell:
    """Answers pair jobs like a registration worker would, but with a stand-in result; ``gate`` holds them."""

    robot = "robot0"

    def __init__(self, gate: asyncio.Event | None = None, delay: float = 0.0):
        self.gate = gate
        self.delay = delay
        self.jobs: list[tuple[int, int]] = []
        self.started = asyncio.Event()
        self.dynamic_config: dict | None = None

    async def register_pair(self, msg):  # noqa: ANN001, ANN201
        from services.registration.dynamic.pair import PairResult
        from services.registration.pair_wire import pair_job_from_message, pair_result_message

        job = pair_job_from_message(msg)
        self.jobs.append((job.source_view, job.target_view))
        self.started.set()
        if self.gate is not None:
            await self.gate.wait()
        await asyncio.sleep(self.delay)  # a worker takes its time: jobs overlap
        T = np.eye(4)
        T[0, 3] = 0.001 * job.source_view  # recognisable per edge
        return pair_result_message(PairResult(job.index, job.source_view, job.target_view, T, 0.8, 0.001, 0.5,
                                              "prior", "full", 0.1))

    async def build_model(self, views, turns, config):  # noqa: ANN001, ANN201
        self.dynamic_config = config
        cloud = views[0].cloud
        return ModelResult(cloud=cloud, figures={"configuration": "no_region"})


def _store_with(tmp_path, view_results, n):
    store = SessionStore(tmp_path)
    for v in view_results[0][:n]:
        store.save_view(v)
    return store


def test_the_state_machine_does_not_wait_on_pair_jobs(tmp_path, view_results):
    async def go():
        store = _store_with(tmp_path, view_results, 2)
        cell = PairCell(gate=asyncio.Event())  # the worker never answers until the gate opens
        acq = Acquisition(cell, store, AcquisitionConfig(views=VIEWS, evaluate=False))  # type: ignore[arg-type]
        acq.j.update(state=State.REGISTER.value, view=1, turns_deg=view_results[1][:2])
        nxt = await asyncio.wait_for(acq.register(), 20)  # view 1 registered: returns with its pair in flight
        assert nxt == State.PLAN_GRASP
        await asyncio.wait_for(cell.started.wait(), 20)
        assert cell.jobs == [(1, 0)] and not (tmp_path / PAIRS_DIR).exists()
        cell.gate.set()
        records = await asyncio.wait_for(acq.incremental.finished(), 20)
        assert [(r["source_view"], r["target_view"]) for r in records] == [(1, 0)]
        assert records[0]["T"][0][3] == pytest.approx(0.001)

    asyncio.run(go())


def test_finished_pairs_survive_a_restart_and_are_not_sent_again(tmp_path, view_results):
    async def first_run():
        store = _store_with(tmp_path, view_results, VIEWS)
        cell = PairCell()
        inc = IncrementalModel(store, {}, cell)
        inc.view_ready(2, view_results[1])  # views 0..2 registered so far: edges 1->0 and 2->1
        return cell, await inc.finished()

    async def killed_mid_job():
        store = SessionStore(tmp_path)
        cell = PairCell(gate=asyncio.Event())
        inc = IncrementalModel(store, {}, cell)
        inc.view_ready(3, view_results[1])  # edge 3->2 goes out; the orchestrator dies before the reply
        await asyncio.wait_for(cell.started.wait(), 20)
        inc.close()
        await asyncio.sleep(0)
        return cell

    async def resumed():
        store = SessionStore(tmp_path)
        cell = PairCell()
        inc = IncrementalModel(store, {}, cell)
        inc.view_ready(3, view_results[1])
        return cell, await inc.finished()

    cell, records = asyncio.run(first_run())
    assert sorted(cell.jobs) == [(1, 0), (2, 1)] and len(records) == 2
    assert asyncio.run(killed_mid_job()).jobs == [(3, 2)]
    assert len(list((tmp_path / PAIRS_DIR).iterdir())) == 2  # nothing half-written for the lost job
    cell, records = asyncio.run(resumed())
    assert cell.jobs == [(3, 2)]  # only the lost one is sent again; the stored two are not
    assert sorted((r["source_view"], r["target_view"]) for r in records) == [(1, 0), (2, 1), (3, 2)]


def test_the_final_request_carries_the_finished_pairs_and_their_palette(tmp_path, view_results):
    async def go():
        store = _store_with(tmp_path, view_results, VIEWS)
        for k in range(VIEWS):  # the last view's scans exist: the model's lateness is measured from them
            (tmp_path / f"view_{k:02d}" / "scan_2").mkdir(parents=True, exist_ok=True)
            (tmp_path / f"view_{k:02d}" / "scan_2" / "meta.json").write_text("{}")
        cell = PairCell(delay=1.0)
        acq = Acquisition(cell, store, AcquisitionConfig(views=VIEWS, evaluate=False))  # type: ignore[arg-type]
        acq.j.update(state=State.MODEL.value, view=VIEWS - 1, turns_deg=view_results[1])
        acq._park = _nothing  # type: ignore[method-assign]
        acq.incremental.view_ready(VIEWS - 1, view_results[1])  # as `register` of the last view did
        assert await asyncio.wait_for(acq.model(), 30) == State.DONE
        return cell, acq

    cell, acq = asyncio.run(go())
    assert sorted(cell.jobs) == [(1, 0), (2, 1), (3, 2)]  # every edge whose views exist was sent, each once
    cfg = cell.dynamic_config
    assert cfg["preprocess"]["palette_views"] == 2 and len(cfg["reuse_pairs"]) == VIEWS - 1
    assert acq.j.model_ready_s_after_last_view is not None


def test_with_the_incremental_model_off_nothing_is_sent_and_nothing_reused(tmp_path, view_results):
    async def go():
        store = _store_with(tmp_path, view_results, VIEWS)
        cell = PairCell()
        acq = Acquisition(cell, store, AcquisitionConfig(views=VIEWS, evaluate=False,  # type: ignore[arg-type]
                                                         incremental=False))
        acq.j.update(state=State.MODEL.value, view=VIEWS - 1, turns_deg=view_results[1])
        acq._park = _nothing  # type: ignore[method-assign]
        await asyncio.wait_for(acq.model(), 30)
        return cell

    cell = asyncio.run(go())
    assert cell.jobs == [] and cell.dynamic_config["reuse_pairs"] == []
    assert "preprocess" not in cell.dynamic_config  # the end-of-run baseline: palette from every view, as before


async def _nothing() -> None:
    return None

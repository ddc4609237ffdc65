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
        # the wire carries the static stage's footprint centre and the height (the table is z = 0 here)
        out.append(ViewResult(view=v.index, cloud=cloud, table=v.table, center=np.asarray(v.center, float) * [1, 1, 0],
                              height=2 * float(v.center[2]), scan_poses=np.zeros((0, 4, 4))))
    return out, [v.commanded_turn_deg for v in scan.views[:VIEWS]]


class PairCell:
    """Answers edge requests as the registration service does (the same ``register_edge``: its jobs built and
    fingerprinted from the views sent), with a stand-in pair result; ``gate`` holds the replies."""

    robot = "robot0"

    def __init__(self, gate: asyncio.Event | None = None, delay: float = 0.0):
        self.gate = gate
        self.delay = delay
        self.jobs: list[tuple[int, int]] = []
        self.background: list[bool] = []
        self.started = asyncio.Event()
        self.dynamic_config: dict | None = None

    def _stand_in(self, jobs):  # noqa: ANN001, ANN202 - a MapPairs: the worker's answer, recognisable per edge
        from services.registration.api import PairResult

        out = []
        for job in jobs:
            T = np.eye(4)
            T[0, 3] = 0.001 * job.source_view
            out.append(PairResult(job.index, job.source_view, job.target_view, T, 0.8, 0.001, 0.5, "prior", "full",
                                  0.1))
        return out

    async def register_edge(self, request):  # noqa: ANN001, ANN201
        from common.api import EdgeRequest
        from services.registration.api import edge_reply, edge_work

        request = EdgeRequest.decode(request.encode())  # what crosses the wire
        jobs = await asyncio.to_thread(edge_work, request)
        for e in jobs:
            self.jobs.append((e.job.source_view, e.job.target_view))
            self.background.append(request.background)
        if jobs:
            self.started.set()
        if self.gate is not None:
            await self.gate.wait()
        await asyncio.sleep(self.delay)  # a worker takes its time: jobs overlap
        return edge_reply(jobs, self._stand_in([e.job for e in jobs]))

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


def test_speculative_jobs_of_the_other_configurations_wait_for_the_foreground(tmp_path, view_results):
    """The first configuration's job goes out at once; the other configurations' jobs of the same edge only
    when no static registration is in flight, one at a time, in configuration order."""
    async def go():
        store = _store_with(tmp_path, view_results, 3)
        cell = PairCell(delay=0.05)
        inc = IncrementalModel(store, {}, cell)
        async with inc.foreground():  # a static registration in flight
            inc.view_ready(1, view_results[1])
            await asyncio.wait_for(cell.started.wait(), 20)
            await asyncio.sleep(1.0)
            assert inc.sent_by_configuration == {"no_region": 1}  # nothing speculative meanwhile
        while inc.sent < 4:
            await asyncio.sleep(0.05)
        assert list(inc.sent_by_configuration) == ["no_region", "no_region_crop", "region", "region_crop"]
        records = await inc.finished()
        return cell, records

    cell, records = asyncio.run(go())
    assert cell.jobs == [(1, 0)] * 4 and len({r["fingerprint"] for r in records}) == 4
    assert cell.background == [False, True, True, True]  # speculative jobs run at the lowest CPU priority


def test_every_configuration_computed_during_the_acquisition_is_reused_at_the_end(tmp_path, service_group,
                                                                                   view_results):
    """Over Zenoh, a real registration worker: the incremental model sends every configuration's neighbour
    jobs as the views arrive; the end (first configuration forced to be rejected, so all four run) computes
    only the four loop closures and reuses the other twelve pairs. ~14 s (a real process, 16 pairs at 3 mm)."""
    from common.client import request as zenoh_request
    from common.launcher import ProcessSpec
    from services.orchestrator.cell import Cell

    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=180)

    async def go():
        session = service_group.session
        cell = Cell(lambda key, msg=None, timeout=60.0: zenoh_request(session, key, msg, timeout=timeout), "robot0")
        store = SessionStore(tmp_path / "session")
        inc = IncrementalModel(store, {"accept": {"min_posed_fitness": 1.01}}, cell)
        views, turns = view_results
        for k, v in enumerate(views):  # the views arrive one by one, as the acquisition registers them
            async with inc.foreground():
                store.save_view(v)
            inc.view_ready(k, turns)
        deadline = asyncio.get_running_loop().time() + 300
        while inc.sent < 4 * (VIEWS - 1):
            assert asyncio.get_running_loop().time() < deadline, inc.sent_by_configuration
            await asyncio.sleep(0.2)
        records = await inc.finished()
        result = await cell.build_model(views, turns, {**inc.config, "reuse_pairs": records})
        return inc, records, result.figures

    inc, records, figures = asyncio.run(go())
    assert inc.sent_by_configuration == {name: VIEWS - 1 for name in
                                         ("no_region", "no_region_crop", "region", "region_crop")}
    assert len(records) == 4 * (VIEWS - 1)
    assert set(figures["candidates"]) == {"no_region", "no_region_crop", "region", "region_crop"}
    assert figures["timings"]["pairs"] == {"reused": 4 * (VIEWS - 1), "computed": 4}

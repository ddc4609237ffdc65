"""``objscan/registration/edge``: the orchestrator sends an edge's views, the registration side builds,
fingerprints and runs the edge's pair jobs and answers their results. In process (``register_edge``) and over
Zenoh (a real registration process), the same results; a stored fingerprint is not run again; a request that
lacks a view the edge needs is a typed error and the service keeps answering."""

from __future__ import annotations

import numpy as np
import pytest

from common import keys
from common.api import EdgeReply, EdgeRequest, ViewResult
from common.client import request_sync
from common.errors import InvalidRequest, RemoteError
from common.launcher import ProcessSpec
from common.messages import PointCloud
from tests.conftest import shared_data


@pytest.fixture(scope="module")
def wire_views():
    """Three views of the milk carton as the static stage answers them (footprint centre, height)."""
    shared_data("hope", "milk")
    from bench.synthetic import synthetic_views

    scan = synthetic_views("milk", views=12, profile="hand-turned", seed=3, voxel=0.003)
    out = []
    for v in scan.views[:3]:
        cloud = PointCloud(xyz=np.asarray(v.xyz, np.float32), rgb=np.asarray(v.rgb, np.uint8),
                           normals=np.asarray(v.normals, np.float32))
        out.append(ViewResult(view=v.index, cloud=cloud, table=v.table, center=np.asarray(v.center, float) * [1, 1, 0],
                              height=2 * float(v.center[2]), scan_poses=np.zeros((0, 4, 4))))
    return out, [float(v.commanded_turn_deg) for v in scan.views[:3]]


def _request(wire_views, **kw) -> EdgeRequest:
    views, turns = wire_views
    fields = {"source": 2, "views": views, "turns_deg": turns, "config": {"preprocess": {"palette_views": 2}},
              "configurations": ["no_region"], **kw}
    return EdgeRequest(**fields)


def test_an_edge_is_answered_with_its_jobs_results_and_known_ones_are_not_run(wire_views):
    from services.registration.api import edge_jobs, register_edge

    request = _request(wire_views)
    views, turns = wire_views
    (expected,) = edge_jobs({v.view: v for v in views}, turns, request.config, 2, ["no_region"])
    ran: list = []
    reply = register_edge(request, lambda jobs: ran.extend(jobs) or [_stand_in(j) for j in jobs])
    assert [j.index for j in ran] == [1] and reply.configurations == ["no_region"]
    (rec,) = reply.records
    assert rec["fingerprint"] == expected.fingerprint
    assert (rec["source_view"], rec["target_view"]) == (2, 1)
    again = register_edge(_request(wire_views, known=[rec["fingerprint"]]), lambda jobs: ran.extend(jobs) or [])
    assert again.records == [] and len(ran) == 1  # stored already: not run again


def test_an_edge_request_without_a_view_it_needs_is_a_typed_error(wire_views):
    from services.registration.api import register_edge

    views, turns = wire_views
    with pytest.raises(InvalidRequest, match=r"lacks view\(s\) \[0\]"):
        register_edge(_request(wire_views, views=views[1:]))


def _stand_in(job):  # noqa: ANN001, ANN202
    from services.registration.api import PairResult

    return PairResult(job.index, job.source_view, job.target_view, np.eye(4), 0.9, 0.001, 0.5, "prior", "full", 0.0)


@pytest.mark.slow
def test_the_registration_service_runs_an_edge_as_it_runs_here(service_group, wire_views):
    """~35 s on a loaded machine: one real pair job at 3 mm in a registration process, and the same job here.
    (The default suite covers the path over Zenoh in tests/orchestrator/test_incremental.py.)"""
    from services.registration.api import register_edge

    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=180)
    request = _request(wire_views)
    there = request_sync(service_group.session, keys.REGISTRATION_EDGE, request, timeout=300)
    assert isinstance(there, EdgeReply), there
    here = register_edge(request)
    assert [r["fingerprint"] for r in there.records] == [r["fingerprint"] for r in here.records]
    assert np.allclose(there.records[0]["T"], here.records[0]["T"], atol=1e-9)
    assert abs(there.records[0]["fitness"] - here.records[0]["fitness"]) < 1e-9
    with pytest.raises(RemoteError) as err:
        request_sync(service_group.session, keys.REGISTRATION_EDGE, _request(wire_views, views=wire_views[0][1:]),
                     timeout=60)
    assert err.value.code == InvalidRequest.code
    known = _request(wire_views, known=[r["fingerprint"] for r in here.records], background=True)
    reply = request_sync(service_group.session, keys.REGISTRATION_EDGE, known, timeout=60)  # still answering
    assert isinstance(reply, EdgeReply) and reply.records == []

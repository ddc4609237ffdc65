"""A live scan and ``objscan reconstruct`` of its recorded session build the same model.

The live path is what an acquisition runs: a real registration service process, on a loopback Zenoh network,
sent each view's scans (``registration/static``), the replies stored in the session folder and loaded back
(the orchestrator's PLY round trip), then the views and their commanded turns (``registration/dynamic``)
with the config the orchestrator sends. The offline path is ``reconstruct`` of the same session folder, in one
process. Both go through ``services.registration.api``; if any step were assembled differently (a view's
centre, the session's pose or turn accuracy, a config default) the models would differ.
"""

from __future__ import annotations

import numpy as np
import pytest

from common import keys
from common.api import DynamicRequest, ModelResult, StaticRequest, ViewResult
from common.client import request_sync
from common.launcher import ProcessSpec
from common.session_folder import read_scan, read_session
from services.registration.api import evaluate_model, read_ply, reconstruct, with_turn_accuracy
from services.session_store import SessionStore
from tests.conftest import shared_data

VIEWS, TURN_DEG = 6, 60.0  # a whole revolution in few views: the test's cost is two dynamic stages


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A recorded session of the twin (realistic error profile), and the object's true surface in ``base``."""
    shared_data("hope", "milk")
    from bench.scenario import simulated_views, write_session
    from services.sim.catalogue import load_object

    frames = simulated_views("milk", views=VIEWS, scans_per_view=3, profile="realistic", seed=0, turn_deg=TURN_DEG)
    session = write_session(tmp_path_factory.mktemp("recorded") / "session", frames)
    T0 = np.asarray(frames[0][0].meta["T_base_object_true"], float).reshape(4, 4)
    pts = load_object("milk").gt_points(20_000, seed=0)
    return session, pts @ T0[:3, :3].T + T0[:3, 3]


def live_model(group, session, out) -> tuple[ModelResult, np.ndarray]:  # noqa: ANN001
    """The session's frames through a running registration service, as an acquisition sends them."""
    info = read_session(session)
    store = SessionStore(out)
    order = [int(v["index"]) for v in info.views]
    for k in order:
        frames = [read_scan(info.path, k, j) for j in info.scans(k)]
        reply = request_sync(group.session, keys.REGISTRATION_STATIC,
                             StaticRequest(frames=frames, view=k, pose_accuracy=info.data["pose_accuracy"]),
                             timeout=600)
        assert isinstance(reply, ViewResult), reply
        store.save_view(reply)
    views = [store.load_view(k) for k in order]
    config = with_turn_accuracy({}, info.data["turn_accuracy_deg"])
    reply = request_sync(group.session, keys.REGISTRATION_DYNAMIC,
                         DynamicRequest(views=views, turns_deg=[info.commanded_turn_deg(k) for k in order],
                                        config=config), timeout=1800)
    assert isinstance(reply, ModelResult), reply
    return reply, read_ply(store.save_model(reply.cloud)).xyz


@pytest.mark.slow  # two static stages and two dynamic stages of 6 views: about a minute idle, more when loaded
@pytest.mark.timeout(2400)  # measured over 10 min on a shared 2-core machine at load 20
def test_a_live_scan_and_reconstruct_of_its_session_build_the_same_model(service_group, recorded, tmp_path):
    session, truth = recorded
    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=180)
    live, live_xyz = live_model(service_group, session, tmp_path / "live")
    report = reconstruct(session, tmp_path / "offline", workers=1, threads=1)
    offline = report["model"]
    assert "error" not in offline, offline
    offline_xyz = read_ply(tmp_path / "offline" / "model.ply").xyz

    assert offline["views_used"] == list(range(VIEWS))
    assert live.figures["views_left_out"] == offline["views_left_out"]
    assert live.figures["configuration"] == offline["configuration"]
    np.testing.assert_allclose(np.asarray(live.figures["T_model_view"]), np.asarray(offline["T_model_view"]),
                               rtol=0, atol=1e-9)
    assert live_xyz.shape == offline_xyz.shape
    init = np.eye(4)
    chamfer_live = evaluate_model(live_xyz, truth, align=True, init_T=init)["chamfer_mm"]
    chamfer_offline = evaluate_model(offline_xyz, truth, align=True, init_T=init)["chamfer_mm"]
    assert abs(chamfer_live - chamfer_offline) <= 1e-6, (chamfer_live, chamfer_offline)

"""Only the orchestrator moves the arm: mutual TLS + the shipped access-control policy, on loopback.

The real arm (sim backend) and its digital twin run as separate processes behind the router of
``deploy/zenoh-router-tls.json5``, each with its own certificate. Sessions with other identities, with no
certificate, with a forged certificate (right CN, wrong CA) or over plain TCP must not move it; the
orchestrator's must. "Not moved" is checked on the arm itself: its joint state is unchanged and its
health counts no request in flight, so the refused request never reached the handler.
"""

from __future__ import annotations

import shutil
import threading
import time

import numpy as np
import pytest
import zenoh

from common import keys
from common.api import CaptureRequest, MoveRequest, MoveResult
from common.client import live_services, request_sync
from common.errors import ServiceUnavailable
from common.messages import Health, JointState, Request, RGBDFrame
from common.zenoh_config import ZenohSettings
from services.cli.cmd_certs import make_ca, make_leaf
from tests.security.tls_cell import TlsCell
from tests.security.tls_router import ROUTER_CONFIG

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is needed to make certificates")

ROBOT = keys.DEFAULT_ROBOT
MOVE = keys.arm(ROBOT, "move")


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    c = TlsCell(tmp_path_factory.mktemp("tls"))
    try:
        c.start_router()
        c.launch(["sim", "arm", "camera"])
        yield c
    finally:
        c.close()


@pytest.fixture(scope="module")
def orchestrator(cell):
    return cell.open("orchestrator")


def _q(session: zenoh.Session) -> np.ndarray:
    state = request_sync(session, keys.arm(ROBOT, "state"), timeout=10)
    assert isinstance(state, JointState)
    return np.asarray(state.position, dtype=float)


def _arm_instance(session: zenoh.Session) -> str:
    return [i for s, i in live_services(session) if s == "arm"][0]


def _arm_busy(session: zenoh.Session, instance: str) -> int:
    """Requests in the arm's handlers right now (Health.busy does not count the health query itself)."""
    h = request_sync(session, keys.health("arm", instance), timeout=5)
    assert isinstance(h, Health)
    return h.busy


def _move_req(q: np.ndarray) -> MoveRequest:
    return MoveRequest(kind="joints", q=np.asarray(q, dtype=np.float64), speed_scale=1.0)


def _attempt_moves(session: zenoh.Session, q_target: np.ndarray) -> list[str]:
    """Every way a session might try to move the arm; returns what each attempt got back."""
    outcomes = []
    for key in (MOVE, keys.arm(ROBOT, "*"), f"objscan/{ROBOT}/**", "objscan/**", keys.arm(ROBOT, "gripper"),
                keys.arm(ROBOT, "stop")):
        replies = list(session.get(key, payload=_move_req(q_target).encode(), timeout=2.0))
        outcomes.append(f"{key}: {len(replies)} replies")
        assert replies == [], f"{key} was answered for an unauthorised session"
    session.put(MOVE, _move_req(q_target).encode())
    return outcomes


@pytest.mark.parametrize("identity", ["camera", "viewer", "grasp", "registration", "sim", "operator"])
def test_other_identities_cannot_move_the_arm(cell, orchestrator, identity):
    q0 = _q(orchestrator)
    target = q0 + np.array([0.25, 0, 0, 0, 0, 0])
    rogue = cell.open(identity)
    busy = []
    stop = threading.Event()
    arm_instance = _arm_instance(orchestrator)

    def watch_busy() -> None:  # a refused request must never be in the arm's handler
        while not stop.is_set():
            busy.append(_arm_busy(orchestrator, arm_instance))
            time.sleep(0.05)

    t = threading.Thread(target=watch_busy)
    t.start()
    try:
        deadline = time.monotonic() + 1.0  # refusals are immediate: keep trying for a while
        while time.monotonic() < deadline:
            _attempt_moves(rogue, target)
            with pytest.raises(ServiceUnavailable):
                request_sync(rogue, MOVE, _move_req(target), timeout=2.0)
        time.sleep(0.3)
    finally:
        stop.set()
        t.join()
    time.sleep(0.3)
    assert np.allclose(_q(orchestrator), q0, atol=1e-6), "the arm moved for an unauthorised session"
    assert len(busy) >= 5 and max(busy) == 0, f"a refused request reached the arm's handler: {busy}"


def test_impostor_arm_cannot_answer_the_orchestrator(cell, orchestrator):
    """A camera declaring the arm's keys (or everything) never receives the orchestrator's commands."""
    rogue = cell.open("camera")
    seen: list[str] = []
    q1 = rogue.declare_queryable(MOVE, lambda q: seen.append(str(q.key_expr)))
    q2 = rogue.declare_queryable("objscan/**", lambda q: seen.append(str(q.key_expr)))
    token = rogue.liveliness().declare_token(keys.alive("arm", "impostor"))
    time.sleep(0.5)
    try:
        assert ("arm", "impostor") not in live_services(orchestrator)
        reply = request_sync(orchestrator, MOVE, _move_req(_q(orchestrator)), timeout=30)
        assert isinstance(reply, MoveResult)
        assert seen == []
    finally:
        q1.undeclare()
        q2.undeclare()
        token.undeclare()


def test_viewer_may_subscribe(cell):
    viewer = cell.open("viewer")
    got: list[bytes] = []
    sub = viewer.declare_subscriber(keys.arm(ROBOT, "state"), lambda s: got.append(s.payload.to_bytes()))
    deadline = time.monotonic() + 5
    while not got and time.monotonic() < deadline:
        time.sleep(0.05)
    sub.undeclare()
    assert got, "a viewer receives the arm's state stream"
    assert isinstance(JointState.decode(got[0]), JointState)


def test_sessions_without_a_valid_certificate_cannot_connect(cell, tmp_path):
    with pytest.raises(zenoh.ZError):  # trusts the CA but shows no certificate
        cell.open(None)
    with pytest.raises(zenoh.ZError):  # plain TCP to the TLS port
        zenoh.open(ZenohSettings(mode="client", connect=[f"tcp/127.0.0.1:{cell.port}"],
                                 connect_timeout_ms=3000).to_zenoh())
    rogue_ca = tmp_path / "rogue"
    ca_cert, ca_key = make_ca(rogue_ca, name="not the lab CA")
    make_leaf(rogue_ca, "orchestrator", ca_cert=ca_cert, ca_key=ca_key)
    forged = cell.settings("orchestrator")
    forged.tls.cert, forged.tls.key = str(rogue_ca / "orchestrator.pem"), str(rogue_ca / "orchestrator.key")
    with pytest.raises(zenoh.ZError):  # right CN, signed by somebody else's CA
        zenoh.open(forged.to_zenoh())


def test_the_orchestrator_moves_the_arm(cell, orchestrator):
    q0 = _q(orchestrator)
    target = q0 + np.array([0.2, 0, 0, 0, 0, 0])
    reply = request_sync(orchestrator, MOVE, _move_req(target), timeout=60)
    assert isinstance(reply, MoveResult)
    assert np.allclose(_q(orchestrator), target, atol=1e-3)
    stopped = request_sync(orchestrator, keys.arm(ROBOT, "stop"), timeout=10)
    assert stopped.info["estopped"] is True
    request_sync(orchestrator, keys.arm(ROBOT, "stop"), Request(params={"reset": True}), timeout=10)
    back = request_sync(orchestrator, MOVE, _move_req(q0), timeout=60)
    assert isinstance(back, MoveResult) and np.allclose(_q(orchestrator), q0, atol=1e-3)


def test_control_without_access_control_the_camera_moves_the_arm(tmp_path):
    """The same attempt succeeds when the policy is switched off: TLS alone does not protect the arm,
    and the refusals above are the policy's doing (this is what the tests above would miss if broken)."""
    text = ROUTER_CONFIG.read_text()
    assert text.count("enabled: true") == 1
    permissive = tmp_path / "router-no-acl.json5"
    permissive.write_text(text.replace("enabled: true", "enabled: false"))
    c = TlsCell(tmp_path / "cell", router_config=permissive)
    try:
        c.start_router()
        c.launch(["sim", "arm"])
        camera = c.open("camera")
        q0 = _q(camera)
        target = q0 + np.array([0.2, 0, 0, 0, 0, 0])
        assert isinstance(request_sync(camera, MOVE, _move_req(target), timeout=60), MoveResult)
        assert np.allclose(_q(camera), target, atol=1e-3)
    finally:
        c.close()


def test_policy_lets_the_cell_work_camera_renders_through_the_twin(cell, orchestrator):
    """The policy is not only restrictive: the camera may still ask the twin to render (camera -> sim/render),
    the arm may still drive the twin (arm -> sim/joints, exercised by every move above), and the
    orchestrator gets the frame."""
    frame = request_sync(orchestrator, keys.camera_capture(ROBOT), CaptureRequest(), timeout=60)
    assert isinstance(frame, RGBDFrame) and frame.depth.size > 0
    viewer = cell.open("viewer")
    with pytest.raises(ServiceUnavailable):  # a viewer may not even ask for a frame
        request_sync(viewer, keys.camera_capture(ROBOT), CaptureRequest(), timeout=2)

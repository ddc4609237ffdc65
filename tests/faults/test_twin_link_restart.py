"""The arm's twin link across a twin restart, without whole acquisitions: a stand-in twin on a real Zenoh
router answers ``sim/joints``, ``sim/world`` and ``sim/gripper`` and holds the sim's liveliness token; it
"dies" (queryables and token gone, as when its process is killed) and "restarts" (declared again, knowing
nothing). The link must re-send the arm's joints to the new twin on its own, make a set-point sent while
the twin is away land once it is back, and start a restarted arm where the twin has it."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest
import zenoh

from common import keys
from common.api import GripperRequest, GripperResult
from common.codec import decode
from common.messages import Error, JointState, Ok
from common.zenoh_config import open_session
from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.drivers.sim.twin_link import TwinLinkedDriver
from services.arm.errors import DriverError
from services.arm.kinematics import Kinematics

pytestmark = pytest.mark.timeout(120)
ROBOT = "twinlink"
Q1 = np.array([0.1, -0.4, -0.8, 0.05, 1.1, -0.1])
Q2 = np.array([0.2, -0.5, -0.7, 0.0, 1.0, 0.1])


class FakeTwin:
    """Just enough of the sim service: records joint states, reports what it knows, can die and restart."""

    def __init__(self, session: zenoh.Session):
        self.session = session
        self.joints: list[JointState] = []
        self.known: JointState | None = None  # what a real twin would have restored
        self.refuse_joints = False
        self._declared: list = []

    def up(self) -> None:
        r = ROBOT
        self._declared = [self.session.declare_queryable(keys.sim(r, op), fn) for op, fn in
                          (("joints", self._joints), ("world", self._world), ("gripper", self._gripper))]
        self._declared.append(self.session.liveliness().declare_token(keys.alive("sim", uuid.uuid4().hex[:8])))

    def down(self, *, forget: bool = True) -> None:
        for d in self._declared:
            d.undeclare()
        self._declared = []
        if forget:
            self.known = None

    @staticmethod
    def _reply(query: zenoh.Query, msg) -> None:  # noqa: ANN001
        query.reply(query.key_expr, msg.encode(), encoding=zenoh.Encoding("application/msgpack"))

    def _joints(self, query: zenoh.Query) -> None:
        msg = decode(query.payload.to_bytes())
        if self.refuse_joints:
            self._reply(query, Error(code="invalid_request", message="no", service="sim"))
            return
        self.joints.append(msg)
        self.known = msg
        self._reply(query, Ok())

    def _world(self, query: zenoh.Query) -> None:
        k = self.known
        info = {} if k is None else {"joint_names": list(k.names), "joint_positions": k.position.tolist(),
                                     "gripper_opening": 0.05}
        self._reply(query, Ok(info=info))

    def _gripper(self, query: zenoh.Query) -> None:
        msg = decode(query.payload.to_bytes())
        assert isinstance(msg, GripperRequest)
        self._reply(query, GripperResult(opening=msg.opening, holding=False, reason="opened"))


@pytest.fixture(scope="module")
def kin():
    return Kinematics()


@pytest.fixture
def cell(service_group):
    twin_session = open_session(service_group.settings)
    arm_session = open_session(service_group.settings)
    twin = FakeTwin(twin_session)
    twin.up()
    try:
        yield twin, arm_session
    finally:
        twin.down()
        arm_session.close()
        twin_session.close()


@contextmanager
def _linked(session: zenoh.Session, kin: Kinematics, **options: object) -> Iterator[TwinLinkedDriver]:
    """A connected twin link, closed afterwards whatever the test did."""
    driver = TwinLinkedDriver(session, ROBOT, kin, **options)
    driver.connect(wait_s=20.0)
    try:
        yield driver
    finally:
        driver.close()


def _wait(pred, timeout: float = 20.0) -> bool:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.05)
    return False


def test_a_restarted_twin_gets_the_joints_without_a_move(cell, kin):
    twin, session = cell
    with _linked(session, kin, retry_window_s=20.0) as driver:
        driver.write_setpoint(Q1)
        assert np.array_equal(twin.joints[-1].position, Q1)
        twin.down()  # killed: it forgets everything
        twin.joints.clear()
        twin.up()  # restarted, nobody moves the arm
        assert _wait(lambda: len(twin.joints) > 0), "the link did not re-send the joints to the new twin"
        last = twin.joints[-1]
        np.testing.assert_array_equal(last.position, Q1)
        np.testing.assert_allclose(last.T_base_camera, kin.fk(Q1, "camera"))  # it renders from the right pose
        assert driver.resyncs >= 1


def test_a_set_point_sent_while_the_twin_is_away_lands_when_it_is_back(cell, kin):
    twin, session = cell
    with _linked(session, kin, retry_window_s=20.0) as driver:
        twin.down()
        done = threading.Event()
        errors: list[BaseException] = []

        def move() -> None:
            try:
                driver.write_setpoint(Q2)
                driver.set_gripper(0.04, 20.0)
            except BaseException as exc:  # noqa: BLE001 - reported below
                errors.append(exc)
            done.set()

        threading.Thread(target=move, daemon=True).start()
        time.sleep(1.0)
        assert not done.is_set(), "the set-point did not wait for the twin"
        twin.up()
        assert done.wait(20.0) and not errors, errors
        np.testing.assert_array_equal(twin.joints[-1].position, Q2)  # newest pose last, whatever re-sent first
        assert driver.retries > 0 and driver.read_gripper() == pytest.approx(0.04)


def test_a_restarted_arm_starts_where_the_twin_has_it(cell, kin):
    twin, session = cell
    twin.known = JointState(names=list(kin.joint_names), position=Q2.copy())
    with _linked(session, kin, config=SimDriverConfig()) as driver:
        np.testing.assert_array_equal(driver.read_joints(), Q2)
        assert driver.read_gripper() == pytest.approx(0.05)
        np.testing.assert_array_equal(twin.joints[0].position, Q2)  # not a jump to initial_q


def test_a_twin_refusing_a_set_point_is_not_retried(cell, kin):
    twin, session = cell
    with _linked(session, kin, retry_window_s=20.0) as driver:
        twin.refuse_joints = True
        t0 = time.monotonic()
        with pytest.raises(DriverError) as err:
            driver.write_setpoint(Q1)
        assert err.value.code == "link_failed" and time.monotonic() - t0 < 5.0 and driver.retries == 0

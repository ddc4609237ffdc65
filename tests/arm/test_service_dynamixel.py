"""The arm service with the *dynamixel* backend on an emulated PAPRAS bus, as a real process over Zenoh.

Moves (and ``home``, which raised AttributeError on this backend before) go through the DYNAMIXEL driver
and dynamixel-sdk to emulated DYNAMIXEL-P servos; the servos' present positions drive the twin, so the
twin's joints end where the servos settled.
"""

from __future__ import annotations

import numpy as np
import pytest

from common import keys
from common.api import GripperRequest, GripperResult, MoveRequest, MoveResult
from common.client import request_sync
from common.launcher import ProcessSpec
from common.messages import Ok, Request
from services.arm.drivers.dynamixel.robot_config import load_robot_config

ROBOT = keys.DEFAULT_ROBOT
pytestmark = pytest.mark.timeout(300)


@pytest.fixture(scope="module")
def hil_cell(tmp_path_factory):
    from common.launcher import ServiceGroup

    with ServiceGroup(log_dir=tmp_path_factory.mktemp("arm-hil-logs")) as group:
        group.launch([ProcessSpec("services.sim", service="sim"),
                      ProcessSpec("services.arm", ["--backend", "dynamixel", "--option", "emulate_bus=true"],
                                  service="arm")],
                     timeout=180)
        yield group


def twin_joints(group) -> np.ndarray:  # noqa: ANN001
    reply = request_sync(group.session, keys.sim(ROBOT, "world"), Request(params={"op": "state"}), timeout=10)
    assert isinstance(reply, Ok)
    return np.asarray(reply.info["joint_positions"])


def test_moves_and_home_on_the_emulated_bus_drive_the_twin(hil_cell):
    home = np.asarray(load_robot_config().home)
    tol = load_robot_config().settle_tolerance
    target = home + np.array([0.3, 0.15, -0.2, 0.25, -0.15, 0.4])
    reply = request_sync(hil_cell.session, keys.arm(ROBOT, "move"), MoveRequest(kind="joints", q=target),
                         timeout=120)
    assert isinstance(reply, MoveResult)
    np.testing.assert_allclose(reply.q, target, atol=tol)
    np.testing.assert_allclose(twin_joints(hil_cell), reply.q, atol=1e-6)  # the twin got the servos' positions
    reply = request_sync(hil_cell.session, keys.arm(ROBOT, "move"), MoveRequest(kind="home"), timeout=120)
    np.testing.assert_allclose(reply.q, home, atol=tol)
    np.testing.assert_allclose(twin_joints(hil_cell), reply.q, atol=1e-6)
    health = request_sync(hil_cell.session, keys.arm(ROBOT, "state"), timeout=10)
    np.testing.assert_allclose(health.position, home, atol=tol)


def test_the_gripper_closes_fully_with_nothing_between_the_fingers(hil_cell):
    reply = request_sync(hil_cell.session, keys.arm(ROBOT, "gripper"), GripperRequest(opening=0.0, force=20.0),
                         timeout=60)
    assert isinstance(reply, GripperResult) and not reply.holding and reply.opening < 0.003
    reply = request_sync(hil_cell.session, keys.arm(ROBOT, "gripper"), GripperRequest(opening=0.106, force=20.0),
                         timeout=60)
    assert reply.opening > 0.1

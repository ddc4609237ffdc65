"""How the arm's sim driver reaches the digital twin over Zenoh.

Every set-point goes to ``sim/joints`` as a request carrying the joints and the TCP/camera poses from
forward kinematics, so the twin moves a held object with the gripper and renders from where the camera
really is; requests keep set-points in order and make a move complete only once the twin has it.
Gripper commands go to ``sim/gripper``, whose answer (the opening the fingers reached on the object)
is what the driver reports back, so ``ArmController.gripper`` detects a grasp exactly as on hardware.
"""

from __future__ import annotations

import time

import numpy as np
import zenoh

from common import keys
from common.api import GripperRequest, GripperResult
from common.client import request_sync
from common.errors import ServiceUnavailable
from common.messages import JointState
from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.drivers.sim.driver import SimArmDriver
from services.arm.kinematics import Kinematics


class TwinLinkedDriver(SimArmDriver):
    """The sim driver wired to the twin: joints with true poses out, measured gripper opening back."""

    def __init__(self, session: zenoh.Session, robot: str, kinematics: Kinematics,
                 config: SimDriverConfig | None = None, timeout: float = 10.0):
        self._session = session
        self._robot = robot
        self._kin = kinematics
        self._timeout = timeout
        super().__init__(send=self._send_joints, config=config)

    def _send_joints(self, q: np.ndarray, opening: float) -> None:
        msg = JointState(names=list(self._kin.joint_names), position=np.asarray(q, dtype=np.float64),
                         T_base_gripper=self._kin.fk(q, "gripper"), T_base_camera=self._kin.fk(q, "camera"),
                         gripper_opening=float(opening))
        request_sync(self._session, keys.sim(self._robot, "joints"), msg, timeout=self._timeout)

    def set_gripper(self, opening_m: float, force: float) -> None:
        self._require()
        reply = request_sync(self._session, keys.sim(self._robot, "gripper"),
                             GripperRequest(opening=float(opening_m), force=float(force)), timeout=self._timeout)
        assert isinstance(reply, GripperResult)
        with self._lock:
            self._opening, self._force = float(reply.opening), float(force)
        self.last_gripper = reply

    def connect(self, wait_s: float = 120.0) -> None:
        """Connect once the twin answers (services start in any order); the twin learns where the arm is."""
        super().connect()
        deadline = time.monotonic() + wait_s
        while True:
            try:
                self._send_joints(self._q, self._opening)
                return
            except ServiceUnavailable:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

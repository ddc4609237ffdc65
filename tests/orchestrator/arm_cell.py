"""An in-process stand-in for ``services.orchestrator.cell.Cell``: the real ``ArmController`` (IK, planning,
envelope and collision checks) on the sim driver, no Zenoh, no twin; the gripper always closes on the object.

It lets the state machine's turn step run against the arm's real refusals in a few seconds.
"""

from __future__ import annotations

import numpy as np

from common.api import GripperResult, MoveResult
from common.errors import RemoteError
from common.messages import JointState
from services.arm.arm import ArmConfig, ArmController
from services.arm.drivers.sim import SimArmDriver
from services.arm.errors import ArmError


class ArmOnlyCell:
    """Moves, gripper, scene and state as the arm service answers them; ``log`` keeps every move."""

    def __init__(self, q0: np.ndarray, kinematics=None):  # noqa: ANN001
        self.arm = ArmController(SimArmDriver(send=lambda q, o: None), ArmConfig(realtime=False), kinematics)
        self.arm.connect()
        self.arm.driver._q = np.asarray(q0, float).copy()
        self.arm._q = self.arm.driver._q.copy()
        self.log: list[dict] = []
        self.holding = False

    async def move(self, kind: str, *, target=None, q=None, frame="gripper", speed=0.5,  # noqa: ANN001
                   free_roll=False, contact=False, dry_run=False, check_opening=None) -> MoveResult:
        a = self.arm
        entry = {"kind": kind, "dry_run": dry_run, "holding": self.holding}
        try:
            if kind == "home":
                info = a.move_joints(np.asarray(a.driver.config.initial_q), speed, dry_run)
            elif kind == "joints":
                info = a.move_joints(q, speed, dry_run)
            elif kind == "pose":
                info = a.move_pose(target, speed, free_roll, frame, contact, dry_run, q if dry_run else None,
                                   check_opening)
            else:
                info = a.move_linear(target, speed, frame, contact, dry_run, q if dry_run else None, check_opening)
        except ArmError as exc:
            self.log.append({**entry, "error": exc.code})
            raise RemoteError(exc.message, code=exc.code) from None
        self.log.append({**entry, "error": None})
        if dry_run:
            f = info["frames_end"]
            return MoveResult(q=info["q_end"], T_base_gripper=f["gripper"], T_base_camera=f["camera"],
                              duration_s=info["duration_s"])
        s = a.state()
        return MoveResult(q=s["q"], T_base_gripper=s["T_base_gripper"], T_base_camera=s["T_base_camera"],
                          duration_s=info["duration_s"])

    async def gripper(self, opening: float, force: float = 30.0) -> GripperResult:
        self.arm._opening = opening
        self.holding = opening == 0.0
        return GripperResult(opening=opening, holding=self.holding)

    async def set_object_box(self, center: np.ndarray, extent: np.ndarray) -> None:
        if float(np.max(extent)) <= 0:
            self.arm.collision.clear_object()
        else:
            self.arm.collision.set_object_box(center, extent)

    async def clear_object_box(self) -> None:
        self.arm.collision.clear_object()

    async def state(self) -> JointState:
        s = self.arm.state()
        return JointState(names=s["names"], position=s["q"], T_base_gripper=s["T_base_gripper"],
                          T_base_camera=s["T_base_camera"])

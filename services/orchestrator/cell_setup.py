"""Getting the cell ready for a new acquisition: the twin reset to the session's object, or the real arm's
stated pose accuracy.

Its own module because it runs once, before the state machine's first state, and only records facts in the
session's config and journal (simulated or not, the camera pose accuracy, the twin's turn accuracy) that
every later static registration and ``reconstruct`` read.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from common.errors import ObjscanError
from common.pose_accuracy import PoseAccuracy
from services.arm.drivers.dynamixel.robot_file import robot_pose_accuracy
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.journal import Journal

#: the gripper's opening the cell starts with (open, ready to grasp)
OPEN_M = 0.1


def state_pose_accuracy(config: AcquisitionConfig, j: Journal, accuracy: dict | None) -> None:
    """Record the arm's camera pose accuracy the cell states (unless the run's config gave one): every
    static registration gets it, and session.json keeps it for ``reconstruct``."""
    if config.pose_accuracy or not accuracy:
        return
    config.pose_accuracy = PoseAccuracy.from_dict(accuracy).to_dict()
    j.config["pose_accuracy"] = config.pose_accuracy


async def prepare_cell(cell: Any, config: AcquisitionConfig, j: Journal, decide: Callable[..., None]) -> None:
    """First start: reset the twin to this session's object/profile/seed (sim cells only; a cell without a
    twin is a real one, whose robot file states its accuracy). Then open the gripper."""
    if j.simulated is None:
        try:
            x, y = config.workspace_center
            form = {k: v for k, v in (("scale", config.object_scale),
                                      ("up_axis", config.object_up_axis)) if v is not None}
            state = await cell.sim("reset", object=config.object, profile=config.profile,
                                   seed=config.seed, x=float(x), y=float(y),
                                   physics=config.physics, **form)
            j.simulated = True
            state_pose_accuracy(config, j, state.get("pose_accuracy"))
            turn_sigma = state.get("turn_accuracy_deg")
            if isinstance(turn_sigma, (int, float)) and turn_sigma > 0:  # session.json keeps it (reconstruct)
                config.turn_accuracy_deg = float(turn_sigma)
                j.config["turn_accuracy_deg"] = config.turn_accuracy_deg
            if config.force_first_slip:
                await cell.sim("force_slip")
        except ObjscanError as exc:
            if exc.code not in ("unavailable", "timeout"):
                raise
            j.simulated = False
            state_pose_accuracy(config, j, robot_pose_accuracy(os.environ.get("OBJSCAN_ROBOT_CONFIG")).to_dict())
        decide("cell ready", simulated=j.simulated, pose_accuracy=config.pose_accuracy)
    await cell.gripper(OPEN_M, config.turn.gripper_force)

"""Typed failures of the arm: every refusal names its reason with a stable ``code``.

Callers (the service face, the orchestrator) branch on ``code``; ``detail`` carries the specifics
(the violated limit, the colliding link pair, the joint index, ...).
"""

from __future__ import annotations

from common.errors import InvalidRequest, ObjscanError


class ArmError(ObjscanError):
    """Base of every arm failure."""

    code = "arm_error"


class BadCommand(InvalidRequest):
    """Malformed command: wrong shape, NaN/inf, not a rigid transform, unknown frame."""

    code = "bad_command"


class IKError(ArmError):
    """No joint solution; ``code`` is ``unreachable``, ``joint_limits`` or ``singular``."""

    code = "unreachable"


class CollisionError(ArmError):
    """A configuration or motion collides; ``detail`` names the pair (``link_a``, ``link_b``)."""

    code = "collision"


class EnvelopeError(ArmError):
    """A command leaves the safety envelope (limits, workspace box, TCP height, gripper force)."""

    code = "out_of_envelope"


class TrajectoryError(ArmError):
    """A trajectory could not be generated (Ruckig failure, discontinuous Cartesian path, ...)."""

    code = "trajectory_failed"


class DriverError(ArmError):
    """Hardware or link failure: a silent servo, a servo error bit, a closed port."""

    code = "driver_error"


class MotionStopped(ArmError):
    """A running motion was halted by an emergency stop (or a stop request)."""

    code = "estop"


class ReadOnlyDriver(ArmError):
    """The driver reports recorded states and cannot move (replay)."""

    code = "read_only"


class RobotConfigError(ArmError):
    """A robot configuration (YAML or dataclass) is invalid; ``detail`` names the key and what was wrong."""

    code = "bad_robot_config"

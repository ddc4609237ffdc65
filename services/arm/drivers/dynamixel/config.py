"""Configuration of the DYNAMIXEL driver: port, baud, per-joint ID/model/offset/direction/limits, the gripper.

The default is the PAPRAS arm as its own ``papras_controls/config/hardware.yaml`` describes it (IDs 1-6,
gripper ID 111, P-series profile units), loaded from the robot configuration shipped in
``services/arm/robot/papras_dynamixel.yaml`` (see ``robot_config.py`` and docs/arm.md). Every field is
validated here, so a configuration built in code fails as clearly as one read from a file.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from functools import lru_cache

from common.backend_options import option
from services.arm.drivers.dynamixel.robot_file import DEFAULT_ROBOT_CONFIG, read_robot_file
from services.arm.drivers.dynamixel.servo_config import (
    BAUD_RATES,
    SHUTDOWN_POLICIES,
    GripperServoConfig,
    JointServoConfig,
    _fail,
)


@dataclass(frozen=True)
class DynamixelOptions:
    """``--option KEY=VALUE`` on the arm service: which robot file, which bus, real or emulated."""

    robot_config: str | None = option(None, "robot configuration YAML (default: the PAPRAS one shipped in "
                                            "services/arm/robot/papras_dynamixel.yaml)", env="OBJSCAN_ROBOT_CONFIG")
    port: str | None = option(None, "serial port of the U2D2 (default: the robot configuration's)")
    baud: int | None = option(None, "bus baud rate (default: the robot configuration's)")
    emulate_bus: bool = option(False, "an emulated bus of the configured servos whose positions drive the twin")


@lru_cache(maxsize=1)
def _papras() -> dict:
    """The shipped PAPRAS robot file's fields, read once (each default below gets its own copy)."""
    return read_robot_file(DEFAULT_ROBOT_CONFIG)


def _default_joints() -> list[JointServoConfig]:
    return copy.deepcopy(_papras()["joints"])


def _default_gripper() -> GripperServoConfig | None:
    return copy.deepcopy(_papras()["gripper"])


# the longest a settle check may wait for the servos after a motion (s): a joint that has not arrived by
# then is blocked or broken, and the arm holds where it is; a longer wait only lets it push longer
MAX_SETTLE_TIMEOUT_S = 5.0


@dataclass
class DynamixelConfig:
    """Bus and servos. ``profile_velocity``/``profile_acceleration`` (rad/s, rad/s^2) are written to a joint
    servo whose own raw values are not set, so the hardware caps the speed even if a set-point were wrong.

    ``shutdown``: ``hold`` keeps torque on at close (the PAPRAS arm falls when limp), ``relax`` turns it
    off. An e-stop always holds (goal = present, torque stays on). ``settle_tolerance``/``settle_timeout_s``:
    after a motion every joint must be within the tolerance of its last set-point, else ``tracking_error``
    (the timeout is bounded: (0, ``MAX_SETTLE_TIMEOUT_S``] s).
    """

    port: str = "/dev/ttyUSB0"
    baudrate: int = 1_000_000
    joints: list[JointServoConfig] = field(default_factory=_default_joints)
    gripper: GripperServoConfig | None = field(default_factory=_default_gripper)
    home: tuple[float, ...] = (0.0, -0.3, -0.9, 0.0, 1.2, 0.0)
    profile_velocity: float = 1.5  # rad/s
    profile_acceleration: float = 4.0  # rad/s^2
    set_operating_mode: bool = True
    error_check_every: int = 10  # set-points between Hardware Error Status reads
    max_tracking_error: float = 0.35  # rad between goal and present before the motion is stopped
    settle_tolerance: float = 0.02  # rad, present vs the final set-point after a motion
    settle_timeout_s: float = 2.0  # at most MAX_SETTLE_TIMEOUT_S: a joint pushing into an obstruction is a fault
    shutdown: str = "hold"
    retries: int = 1  # extra attempts of a failed read before a servo is declared silent

    def __post_init__(self) -> None:
        if not isinstance(self.port, str) or not self.port:
            raise _fail("port", "the serial port is a device path such as /dev/ttyUSB0", value=repr(self.port))
        if self.baudrate not in BAUD_RATES:
            raise _fail("baudrate", "not a DYNAMIXEL baud rate", value=self.baudrate, allowed=list(BAUD_RATES))
        if len(self.joints) != 6:
            raise _fail("joints", "the PAPRAS arm needs exactly 6 joint servos", found=len(self.joints))
        ids = [j.dxl_id for j in self.joints] + ([self.gripper.dxl_id] if self.gripper else [])
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise _fail("joints", "every servo needs its own ID", duplicated=dup)
        if len(self.home) != 6 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in self.home):
            raise _fail("home", "home is 6 joint angles in rad", value=list(self.home))
        self.home = tuple(float(v) for v in self.home)
        if self.shutdown not in SHUTDOWN_POLICIES:
            raise _fail("shutdown", "shutdown is 'hold' or 'relax'", value=self.shutdown)
        for k in ("profile_velocity", "profile_acceleration", "max_tracking_error", "settle_tolerance",
                  "settle_timeout_s"):
            v = getattr(self, k)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise _fail(k, "must be a positive number", value=repr(v))
        if self.settle_timeout_s > MAX_SETTLE_TIMEOUT_S:
            raise _fail("settle_timeout_s", f"the settle check waits at most {MAX_SETTLE_TIMEOUT_S} s",
                        value=self.settle_timeout_s, max=MAX_SETTLE_TIMEOUT_S)


__all__ = ["DynamixelConfig", "GripperServoConfig", "JointServoConfig"]

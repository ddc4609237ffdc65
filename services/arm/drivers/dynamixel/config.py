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

from services.arm.drivers.dynamixel.control_table import RH_P12_RN_A, ControlTable, table_for
from services.arm.errors import RobotConfigError

BAUD_RATES = (9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000, 10_500_000)
SHUTDOWN_POLICIES = ("hold", "relax")


def _fail(key: str, message: str, **detail: object) -> RobotConfigError:
    return RobotConfigError(f"{key}: {message}", detail={"key": key, **detail})


def _check_id(key: str, dxl_id: object) -> None:
    if not isinstance(dxl_id, int) or isinstance(dxl_id, bool) or not 0 <= dxl_id <= 252:
        raise _fail(key, "a DYNAMIXEL ID is an integer 0..252", value=repr(dxl_id))


def _model_table(key: str, model: str) -> ControlTable:
    try:
        return table_for(model)
    except KeyError:
        from services.arm.drivers.dynamixel.control_table import MODELS

        raise _fail(key, f"unknown model {model!r}", known=sorted(MODELS)) from None


def _check_raw(key: str, value: object) -> None:
    if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < 0):
        raise _fail(key, "a raw register value is a non-negative integer", value=repr(value))


@dataclass
class JointServoConfig:
    """One joint. q = offset_rad + direction * (ticks - center) * 2 pi / ticks_per_rev (from the model).

    ``profile_velocity``/``profile_acceleration`` are raw register values in the model's units (P series:
    0.01 rev/min and 1 rev/min^2, as hardware.yaml writes them); None derives them from
    ``DynamixelConfig.profile_velocity``/``profile_acceleration`` (rad/s, rad/s^2). ``homing_offset``
    (pulses, EEPROM) and ``return_delay_time`` (2 µs units, EEPROM) are written at connect when set.
    ``limits`` (rad) are refused by the driver before they reach the bus.
    """

    dxl_id: int
    model: str = "XM430-W350"
    offset_rad: float = 0.0
    direction: int = 1
    limits: tuple[float, float] | None = None
    profile_velocity: int | None = None
    profile_acceleration: int | None = None
    homing_offset: int | None = None
    return_delay_time: int | None = None
    name: str = ""

    def __post_init__(self) -> None:
        key = self.name or f"joint id {self.dxl_id}"
        _check_id(f"{key}.id", self.dxl_id)
        _model_table(f"{key}.model", self.model)
        if self.direction not in (1, -1):
            raise _fail(f"{key}.direction", "direction is 1 or -1", value=repr(self.direction))
        if not isinstance(self.offset_rad, (int, float)) or not math.isfinite(self.offset_rad):
            raise _fail(f"{key}.offset", "the zero offset is a finite angle in rad", value=repr(self.offset_rad))
        if self.limits is not None:
            lo, hi = (float(v) for v in self.limits)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise _fail(f"{key}.limits", "limits are [lower, upper] in rad with lower < upper",
                            value=list(self.limits))
            self.limits = (lo, hi)
        for k in ("profile_velocity", "profile_acceleration", "return_delay_time"):
            _check_raw(f"{key}.{k}", getattr(self, k))
        if self.homing_offset is not None and not isinstance(self.homing_offset, int):
            raise _fail(f"{key}.homing_offset", "the homing offset is an integer (pulses)")

    @property
    def table(self) -> ControlTable:
        return table_for(self.model)

    def to_ticks(self, q: float) -> int:
        t = self.table
        return int(round(t.center_tick + self.direction * (q - self.offset_rad) * t.ticks_per_rev / (2 * math.pi)))

    def to_rad(self, ticks: int) -> float:
        t = self.table
        return self.offset_rad + self.direction * (ticks - t.center_tick) * 2 * math.pi / t.ticks_per_rev


@dataclass
class GripperServoConfig:
    """The RH-P12-RN(A): Goal Position 0 = open, 740 = closed (e-manual figures), stroke 106 mm (rev 1).

    Assumptions (documented in docs/arm.md): the opening is linear in the position pulses between
    ``ticks_open`` and ``ticks_closed``, and the grip force is proportional to Goal Current, 170 N
    (the rated maximum) at the 1,984 mA Current Limit.
    """

    dxl_id: int = 111
    model: str = RH_P12_RN_A.name
    ticks_open: int = 0
    ticks_closed: int = 740
    stroke_m: float = 0.106
    current_limit_ma: int = 1984
    newtons_per_ma: float = 170.0 / 1984.0
    profile_velocity: int | None = None
    profile_acceleration: int | None = None
    return_delay_time: int | None = None
    name: str = "robot1/gripper"

    def __post_init__(self) -> None:
        _check_id(f"{self.name}.id", self.dxl_id)
        _model_table(f"{self.name}.model", self.model)
        for k in ("profile_velocity", "profile_acceleration", "return_delay_time"):
            _check_raw(f"{self.name}.{k}", getattr(self, k))
        if self.ticks_open == self.ticks_closed:
            raise _fail(f"{self.name}.ticks_open", "open and closed positions must differ")

    @property
    def table(self) -> ControlTable:
        return table_for(self.model)

    def to_ticks(self, opening_m: float) -> int:
        frac = min(max(opening_m / self.stroke_m, 0.0), 1.0)
        return int(round(self.ticks_closed + frac * (self.ticks_open - self.ticks_closed)))

    def to_opening(self, ticks: int) -> float:
        frac = (ticks - self.ticks_closed) / (self.ticks_open - self.ticks_closed)
        return float(min(max(frac, 0.0), 1.0) * self.stroke_m)

    def current_ma(self, force_n: float) -> int:
        return int(min(max(round(force_n / self.newtons_per_ma), 0), self.current_limit_ma))


@lru_cache(maxsize=1)
def _papras() -> DynamixelConfig:
    from services.arm.drivers.dynamixel.robot_config import load_robot_config

    return load_robot_config()


def _default_joints() -> list[JointServoConfig]:
    return copy.deepcopy(_papras().joints)


def _default_gripper() -> GripperServoConfig | None:
    return copy.deepcopy(_papras().gripper)


@dataclass
class DynamixelConfig:
    """Bus and servos. ``profile_velocity``/``profile_acceleration`` (rad/s, rad/s^2) are written to a joint
    servo whose own raw values are not set, so the hardware caps the speed even if a set-point were wrong.

    ``shutdown``: ``hold`` keeps torque on at close (the PAPRAS arm falls when limp), ``relax`` turns it
    off. An e-stop always holds (goal = present, torque stays on). ``settle_tolerance``/``settle_timeout_s``:
    after a motion every joint must be within the tolerance of its last set-point, else ``tracking_error``.
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
    settle_timeout_s: float = 2.0
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

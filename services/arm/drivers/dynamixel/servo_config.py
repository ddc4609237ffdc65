"""Servo entries of the DYNAMIXEL configuration: one joint servo, the gripper servo, and their checks.

Kept apart from ``config.py`` (the whole bus) so the robot configuration file's parser can build servo
entries without importing the bus configuration whose defaults it provides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from services.arm.drivers.dynamixel.control_table import MODELS, RH_P12_RN_A, ControlTable, table_for
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



"""Control-table layouts the driver and the emulator need (addresses in bytes, Protocol 2.0).

Sources, checked against each other: dynamixel-sdk 4.1's own model files
(``dynamixel_easy_sdk/control_table/{xm430_w350,ph54_200_s500,ph54_100_s500,ph42_020_s300,pm54_060_s250,
pm54_040_s250,pm42_010_s260,rh_p12_rn}.model`` and ``dynamixel.model`` for the model numbers) and the
ROBOTIS e-manual pages of the same servos.

- X series (XM/XH/XW): Torque Enable 64, Goal Position 116, Present Position 132; 4,096 pulses per turn
  with 2,048 at 0 rad; Profile Velocity in 0.229 rev/min, Profile Acceleration in 214.577 rev/min^2.
- DYNAMIXEL-P (PH54, PH42, PM54, PM42) and the RH-P12-RN(A) gripper firmware share one layout: Torque
  Enable 512, Hardware Error Status 518, Goal Current 550, Profile Acceleration 556, Profile Velocity 560,
  Goal Position 564, Present Current 574, Present Position 580; 0 pulses at 0 rad and ±501,923 (PH54),
  ±303,750 (PH42), ±251,417 (PM54), ±263,187 (PM42) pulses at ±π; Profile Velocity in 0.01 rev/min,
  Profile Acceleration in 1 rev/min^2.

The EEPROM area (below Torque Enable) is writable only while torque is off: Operating Mode 11, Homing
Offset 20, Return Delay Time 9, Position Limits 48/52, on both layouts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# addresses common to every Protocol 2.0 servo used here (X and P layouts agree on them)
MODEL_NUMBER = 0
FIRMWARE_VERSION = 6
RETURN_DELAY_TIME = 9
OPERATING_MODE = 11
HOMING_OFFSET = 20
MAX_POSITION_LIMIT = 48
MIN_POSITION_LIMIT = 52

# Hardware Error Status bits (same meaning on X and P), for messages
HARDWARE_ERROR_BITS = {
    0: "input voltage",
    1: "motor hall sensor",
    2: "overheating",
    3: "motor encoder",
    4: "electrical shock",
    5: "overload",
}


def describe_hardware_error(bits: int) -> list[str]:
    """The named faults in a Hardware Error Status value (unknown bits as ``bit N``)."""
    return [HARDWARE_ERROR_BITS.get(b, f"bit {b}") for b in range(8) if bits >> b & 1]


@dataclass(frozen=True)
class ControlTable:
    """One servo model: its model number, the RAM addresses the driver uses, and its units."""

    name: str
    model_number: int
    torque_enable: int
    hardware_error: int
    goal_current: int
    profile_acceleration: int
    profile_velocity: int
    goal_position: int
    present_current: int
    present_position: int
    eeprom_end: int  # writes below this address need torque off
    velocity_unit_rpm: float  # Profile Velocity unit, rev/min
    acceleration_unit_rpm2: float  # Profile Acceleration unit, rev/min^2
    position_mode: int  # Operating Mode value for (current-based) position control
    ticks_per_rev: int  # position pulses per turn
    center_tick: int  # pulses at 0 rad
    operating_mode: int = OPERATING_MODE
    max_position_limit: int = MAX_POSITION_LIMIT
    min_position_limit: int = MIN_POSITION_LIMIT
    homing_offset: int = HOMING_OFFSET
    return_delay_time: int = RETURN_DELAY_TIME

    @property
    def layout(self) -> tuple[int, int]:
        """Servos with the same layout can share one sync read/write (same addresses)."""
        return (self.goal_position, self.present_position)

    def rad_per_s(self, raw_velocity: int) -> float:
        return raw_velocity * self.velocity_unit_rpm * 2 * math.pi / 60.0

    def rad_per_s2(self, raw_acceleration: int) -> float:
        return raw_acceleration * self.acceleration_unit_rpm2 * 2 * math.pi / 3600.0

    def raw_velocity(self, rad_per_s: float) -> int:
        return max(int(rad_per_s * 60.0 / (2 * math.pi) / self.velocity_unit_rpm), 1)

    def raw_acceleration(self, rad_per_s2: float) -> int:
        return max(int(rad_per_s2 * 3600.0 / (2 * math.pi) / self.acceleration_unit_rpm2), 1)


def _x(name: str, model_number: int) -> ControlTable:
    return ControlTable(name=name, model_number=model_number, torque_enable=64, hardware_error=70, goal_current=102,
                        profile_acceleration=108, profile_velocity=112, goal_position=116, present_current=126,
                        present_position=132, eeprom_end=64, velocity_unit_rpm=0.229, acceleration_unit_rpm2=214.577,
                        position_mode=3, ticks_per_rev=4096, center_tick=2048)


def _p(name: str, model_number: int, half_turn: int, position_mode: int = 3,
       velocity_unit_rpm: float = 0.01) -> ControlTable:
    return ControlTable(name=name, model_number=model_number, torque_enable=512, hardware_error=518, goal_current=550,
                        profile_acceleration=556, profile_velocity=560, goal_position=564, present_current=574,
                        present_position=580, eeprom_end=512, velocity_unit_rpm=velocity_unit_rpm,
                        acceleration_unit_rpm2=1.0,
                        position_mode=position_mode, ticks_per_rev=2 * half_turn, center_tick=0)


X_SERIES = _x("XM430-W350", 1020)
XM430_W210 = _x("XM430-W210", 1030)
PH42_020 = _p("PH42-020-S300-R", 2000, 303_750)
PH54_100 = _p("PH54-100-S500-R", 2010, 501_923)
PH54_200 = _p("PH54-200-S500-R", 2020, 501_923)
PM42_010 = _p("PM42-010-S260-R", 2100, 263_187)
PM54_040 = _p("PM54-040-S250-R", 2110, 251_417)
PM54_060 = _p("PM54-060-S250-R", 2120, 251_417)
# the gripper: 0 = open, 740 = closed (limits 0..1,150); current-based position control (5); velocity
# unit 0.114 rev/min (the SDK model file's 0.0119380521 rad/s)
RH_P12_RN_A = _p("RH-P12-RN(A)", 35074, 740, position_mode=5, velocity_unit_rpm=0.114)

MODELS: dict[str, ControlTable] = {
    t.name: t for t in (X_SERIES, XM430_W210, PH42_020, PH54_100, PH54_200, PM42_010, PM54_040, PM54_060, RH_P12_RN_A)
}
BY_NUMBER: dict[int, ControlTable] = {t.model_number: t for t in MODELS.values()}


def table_for(model: str) -> ControlTable:
    """The table of a model name (``PH54-200-S500-R``; case and a trailing ``-R`` are forgiven)."""
    key = model.strip().upper()
    for name, t in MODELS.items():
        if key in (name.upper(), name.upper().removesuffix("-R")):
            return t
    raise KeyError(model)


def model_name(model_number: int) -> str:
    t = BY_NUMBER.get(model_number)
    return t.name if t else f"unknown model {model_number}"

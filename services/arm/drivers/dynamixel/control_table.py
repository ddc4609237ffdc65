"""Control-table layouts the driver and the emulator need (addresses in bytes, Protocol 2.0).

``X_SERIES``: XM/XH/XW servos, from dynamixel-sdk's own ``dynamixel_easy_sdk/control_table/xm430_w350.model``
and the X-series e-manual. ``P_SERIES``: DYNAMIXEL-P / PRO(A) layout, which the RH-P12-RN(A) gripper
firmware shares (ROBOTIS e-manual, RH-P12-RN(A) page: Torque Enable 512, Goal Current 550, Profile
Acceleration 556, Profile Velocity 560, Goal Position 564, Present Current 574, Present Position 580,
Hardware Error Status 518, Position Limits 48/52 (0..1,150 pulses for the gripper)).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ControlTable:
    name: str
    model_number: int
    operating_mode: int
    torque_enable: int
    hardware_error: int
    goal_current: int
    profile_acceleration: int
    profile_velocity: int
    goal_position: int
    present_current: int
    present_position: int
    max_position_limit: int
    min_position_limit: int
    eeprom_end: int  # writes below this address need torque off
    velocity_unit_rpm: float  # Profile Velocity unit, rev/min
    acceleration_unit_rpm2: float  # Profile Acceleration unit, rev/min^2
    position_mode: int  # Operating Mode value for (current-based) position control


X_SERIES = ControlTable(
    name="XM430-W350",
    model_number=1020,
    operating_mode=11,
    torque_enable=64,
    hardware_error=70,
    goal_current=102,
    profile_acceleration=108,
    profile_velocity=112,
    goal_position=116,
    present_current=126,
    present_position=132,
    max_position_limit=48,
    min_position_limit=52,
    eeprom_end=64,
    velocity_unit_rpm=0.229,
    acceleration_unit_rpm2=214.577,
    position_mode=3,
)

RH_P12_RN_A = ControlTable(
    name="RH-P12-RN(A)",
    model_number=35074,
    operating_mode=11,
    torque_enable=512,
    hardware_error=518,
    goal_current=550,
    profile_acceleration=556,
    profile_velocity=560,
    goal_position=564,
    present_current=574,
    present_position=580,
    max_position_limit=48,
    min_position_limit=52,
    eeprom_end=512,
    velocity_unit_rpm=0.01,
    acceleration_unit_rpm2=1.0,
    position_mode=5,  # current-based position control
)

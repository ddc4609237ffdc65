"""Configuration of the DYNAMIXEL driver: port, baud, per-joint IDs/offsets/directions, the gripper.

Defaults describe a PAPRAS arm on one U2D2: joints 1..6 as IDs 1..6 (X-series control table), the
RH-P12-RN gripper as ID 7 with the RH-P12-RN(A) firmware. Check them against your arm (DYNAMIXEL
Wizard 2.0 scan) before the first run; docs/arm.md explains how.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from services.arm.drivers.dynamixel.control_table import RH_P12_RN_A, X_SERIES, ControlTable


@dataclass
class JointServoConfig:
    """One joint: q = offset_rad + direction * (ticks - center_tick) * 2 pi / ticks_per_rev."""

    dxl_id: int
    offset_rad: float = 0.0
    direction: int = 1
    ticks_per_rev: int = 4096
    center_tick: int = 2048

    def to_ticks(self, q: float) -> int:
        return int(
            round(self.center_tick + self.direction * (q - self.offset_rad) * self.ticks_per_rev / (2 * math.pi))
        )

    def to_rad(self, ticks: int) -> float:
        return self.offset_rad + self.direction * (ticks - self.center_tick) * 2 * math.pi / self.ticks_per_rev


@dataclass
class GripperServoConfig:
    """The RH-P12-RN(A): Goal Position 0 = open, 740 = closed (e-manual figures), stroke 106 mm (rev 1).

    Assumptions (documented in docs/arm.md): the opening is linear in the position pulses between
    ``ticks_open`` and ``ticks_closed``, and the grip force is proportional to Goal Current, 170 N
    (the rated maximum) at the 1,984 mA Current Limit.
    """

    dxl_id: int = 7
    table: ControlTable = RH_P12_RN_A
    ticks_open: int = 0
    ticks_closed: int = 740
    stroke_m: float = 0.106
    current_limit_ma: int = 1984
    newtons_per_ma: float = 170.0 / 1984.0

    def to_ticks(self, opening_m: float) -> int:
        frac = min(max(opening_m / self.stroke_m, 0.0), 1.0)
        return int(round(self.ticks_closed + frac * (self.ticks_open - self.ticks_closed)))

    def to_opening(self, ticks: int) -> float:
        frac = (ticks - self.ticks_closed) / (self.ticks_open - self.ticks_closed)
        return float(min(max(frac, 0.0), 1.0) * self.stroke_m)

    def current_ma(self, force_n: float) -> int:
        return int(min(max(round(force_n / self.newtons_per_ma), 0), self.current_limit_ma))


@dataclass
class DynamixelConfig:
    """Bus and servos. ``profile_velocity``/``profile_acceleration`` (rad/s, rad/s^2) are written to every
    joint servo so the hardware itself caps the speed even if a set-point were wrong."""

    port: str = "/dev/ttyUSB0"
    baudrate: int = 1_000_000
    joints: list[JointServoConfig] = field(default_factory=lambda: [JointServoConfig(i) for i in range(1, 7)])
    joint_table: ControlTable = X_SERIES
    gripper: GripperServoConfig | None = field(default_factory=GripperServoConfig)
    profile_velocity: float = 1.5  # rad/s
    profile_acceleration: float = 4.0  # rad/s^2
    set_operating_mode: bool = True
    error_check_every: int = 10  # set-points between Hardware Error Status reads
    max_tracking_error: float = 0.35  # rad between goal and present before the motion is stopped
    torque_off_on_close: bool = False  # the PAPRAS arm falls when limp: keep torque unless asked
    retries: int = 1  # extra attempts of a failed read before a servo is declared silent

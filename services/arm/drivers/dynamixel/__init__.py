"""DYNAMIXEL backend (Protocol 2.0 over dynamixel-sdk, X and P series), on a real or an emulated bus.

Options (``--option KEY=VALUE`` on the arm service, ``DynamixelOptions``): ``robot_config`` (YAML, default:
PAPRAS), ``port``/``baud`` (override the file's), and ``emulate_bus``: run the real driver against an emulated
P-series bus whose servo positions drive the digital twin (hardware in the loop, ``hil.py``).
"""

from __future__ import annotations

from typing import Any

from services.arm.drivers.dynamixel.config import (
    DynamixelConfig,
    DynamixelOptions,
    GripperServoConfig,
    JointServoConfig,
)
from services.arm.drivers.registry import DriverContext, DriverEntry


def _config(options: DynamixelOptions) -> DynamixelConfig:
    from services.arm.drivers.dynamixel.robot_config import load_robot_config

    return load_robot_config(options.robot_config, port=options.port, baudrate=options.baud)


def _factory(config: DynamixelConfig, ctx: DriverContext):  # noqa: ANN202 - a DynamixelArmDriver
    if ctx.options.get("emulate_bus"):
        from services.arm.drivers.dynamixel.hil import EmulatedBusDriver
        from services.arm.drivers.sim.twin_link import TwinLinkedDriver

        return EmulatedBusDriver(config, TwinLinkedDriver(ctx.session, ctx.robot, ctx.kinematics))
    from services.arm.drivers.dynamixel.driver import DynamixelArmDriver

    return DynamixelArmDriver(config)


def __getattr__(name: str) -> Any:  # the driver imports dynamixel-sdk: only when asked for
    if name == "DynamixelArmDriver":
        from services.arm.drivers.dynamixel.driver import DynamixelArmDriver

        return DynamixelArmDriver
    raise AttributeError(name)


DRIVER = DriverEntry("dynamixel", DynamixelConfig, DynamixelOptions, _config, _factory, realtime=True,
                     description="DYNAMIXEL X/P servos over a U2D2 (or the emulated bus)")

__all__ = ["DRIVER", "DynamixelArmDriver", "DynamixelConfig", "DynamixelOptions", "GripperServoConfig",
           "JointServoConfig"]

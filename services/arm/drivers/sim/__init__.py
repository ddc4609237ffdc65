"""Sim backend: joint set-points to the digital twin."""

from __future__ import annotations

from services.arm.drivers.registry import DriverContext, DriverEntry
from services.arm.drivers.sim.config import SimDriverConfig, SimDriverOptions
from services.arm.drivers.sim.driver import SimArmDriver


def _factory(config: SimDriverConfig, ctx: DriverContext) -> SimArmDriver:
    from services.arm.drivers.sim.twin_link import TwinLinkedDriver

    return TwinLinkedDriver(ctx.session, ctx.robot, ctx.kinematics, config)


def _config(options: SimDriverOptions) -> SimDriverConfig:
    return SimDriverConfig()


DRIVER = DriverEntry("sim", SimDriverConfig, SimDriverOptions, _config, _factory, realtime=False,
                     description="the digital twin over Zenoh (services/sim)")

__all__ = ["DRIVER", "SimArmDriver", "SimDriverConfig"]

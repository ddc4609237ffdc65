"""Replay backend: recorded joint states, no motion."""

from __future__ import annotations

from services.arm.drivers.registry import DriverContext, DriverEntry
from services.arm.drivers.replay.config import ReplayDriverConfig, ReplayDriverOptions
from services.arm.drivers.replay.driver import ReplayArmDriver


def _config(options: ReplayDriverOptions) -> ReplayDriverConfig:
    return ReplayDriverConfig(options.session)


def _factory(config: ReplayDriverConfig, ctx: DriverContext) -> ReplayArmDriver:
    return ReplayArmDriver.from_session(config.session)


DRIVER = DriverEntry("replay", ReplayDriverConfig, ReplayDriverOptions, _config, _factory, realtime=False,
                     description="recorded joints of a session folder; refuses motion")

__all__ = ["DRIVER", "ReplayArmDriver", "ReplayDriverConfig"]

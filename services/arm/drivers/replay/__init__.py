"""Replay backend: recorded joint states, no motion."""

from __future__ import annotations

from typing import Any

from services.arm.drivers.registry import DriverContext, DriverEntry
from services.arm.drivers.replay.config import ReplayDriverConfig
from services.arm.drivers.replay.driver import ReplayArmDriver


def _config(options: dict[str, Any]) -> ReplayDriverConfig:
    return ReplayDriverConfig(options.get("session") or "")


def _factory(config: ReplayDriverConfig, ctx: DriverContext) -> ReplayArmDriver:
    return ReplayArmDriver.from_session(config.session)


DRIVER = DriverEntry("replay", ReplayDriverConfig, _config, _factory, realtime=False,
                     description="recorded joints of a session folder; refuses motion")

__all__ = ["DRIVER", "ReplayArmDriver", "ReplayDriverConfig"]

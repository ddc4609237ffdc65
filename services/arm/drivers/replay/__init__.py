"""Replay backend: recorded joint states, no motion."""

from services.arm.drivers.replay.driver import ReplayArmDriver

__all__ = ["ReplayArmDriver"]

"""Arm drivers behind one interface (``base.ArmDriver``): ``sim``, ``dynamixel``, ``replay``."""

from services.arm.drivers.base import ArmDriver, ExecutionResult, execute

__all__ = ["ArmDriver", "ExecutionResult", "execute"]

"""Arm drivers behind one interface (``base.ArmDriver``): ``sim``, ``dynamixel``, ``replay``.

Each backend is one folder with its config class and a ``DRIVER`` entry; ``registry.py`` maps the backend
name to the folder (``make_driver(name, context)``)."""

from services.arm.drivers.base import ArmDriver, ExecutionResult, execute

__all__ = ["ArmDriver", "ExecutionResult", "execute"]

"""Sim backend: joint set-points to the digital twin."""

from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.drivers.sim.driver import SimArmDriver

__all__ = ["SimArmDriver", "SimDriverConfig"]

"""DYNAMIXEL backend (Protocol 2.0 over dynamixel-sdk) and an emulated bus for tests and bench work."""

from services.arm.drivers.dynamixel.config import DynamixelConfig, GripperServoConfig, JointServoConfig
from services.arm.drivers.dynamixel.driver import DynamixelArmDriver

__all__ = ["DynamixelArmDriver", "DynamixelConfig", "GripperServoConfig", "JointServoConfig"]

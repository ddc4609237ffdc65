"""The arm driver registry: backend name -> config class -> factory; a new backend is one folder + one line."""

from __future__ import annotations

import pytest

from services.arm.drivers.base import ArmDriver
from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.drivers.registry import BACKENDS, DriverContext, driver_entry, make_driver
from services.arm.drivers.replay.config import ReplayDriverConfig
from services.arm.drivers.sim.config import SimDriverConfig
from services.arm.errors import BadCommand, RobotConfigError


def test_every_backend_resolves_to_its_folder_entry():
    assert set(BACKENDS) == {"sim", "dynamixel", "replay"}
    classes = {name: driver_entry(name).config_class for name in BACKENDS}
    assert classes == {"sim": SimDriverConfig, "dynamixel": DynamixelConfig, "replay": ReplayDriverConfig}
    assert driver_entry("dynamixel").realtime and not driver_entry("sim").realtime


def test_dynamixel_options_become_its_config(tmp_path):
    entry = driver_entry("dynamixel")
    cfg = entry.config_from_options({"port": "/dev/ttyUSB7", "baud": 57600})
    assert isinstance(cfg, DynamixelConfig) and cfg.port == "/dev/ttyUSB7" and cfg.baudrate == 57600
    assert [j.dxl_id for j in cfg.joints] == [1, 2, 3, 4, 5, 6]  # the PAPRAS file
    drv, _ = make_driver("dynamixel", DriverContext(options={"port": "/dev/ttyUSB7"}))
    assert isinstance(drv, ArmDriver) and drv.name == "dynamixel" and drv.config.port == "/dev/ttyUSB7"
    with pytest.raises(RobotConfigError):
        make_driver("dynamixel", DriverContext(options={"robot_config": str(tmp_path / "none.yaml")}))


def test_unknown_backend_and_replay_without_a_session_are_typed_errors():
    with pytest.raises(BadCommand) as e:
        driver_entry("ros2")
    assert e.value.code == "unknown_backend" and e.value.detail["known"] == ["dynamixel", "replay", "sim"]
    with pytest.raises(BadCommand):
        make_driver("replay", DriverContext(options={}))

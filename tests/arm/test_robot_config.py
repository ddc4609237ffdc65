"""The robot configuration file: the PAPRAS default matches PAPRAS's own hardware.yaml; bad files are refused
with an error naming the key."""

from __future__ import annotations

import copy

import pytest
import yaml

from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.drivers.dynamixel.robot_config import (
    DEFAULT_ROBOT_CONFIG,
    load_robot_config,
    robot_config_from_dict,
)
from services.arm.errors import RobotConfigError
from tests.conftest import shared_data


def test_papras_default_matches_its_hardware_yaml():
    hw = yaml.safe_load((shared_data() / "papras/PAPRAS-V0-Public/papras_controls/config/hardware.yaml").read_text())
    cfg = load_robot_config()
    assert cfg == DynamixelConfig()  # the driver's default is this file
    servos = {j.name: j for j in cfg.joints}
    servos[cfg.gripper.name] = cfg.gripper
    assert set(servos) == set(hw)
    for name, entry in hw.items():
        s = servos[name]
        assert s.dxl_id == entry["ID"]
        assert s.profile_velocity == entry["Profile_Velocity"]
        assert s.profile_acceleration == entry["Profile_Acceleration"]
        assert s.return_delay_time == entry["Return_Delay_Time"]
        assert getattr(s, "homing_offset", None) == entry.get("Homing_Offset")
    assert [j.dxl_id for j in cfg.joints] == [1, 2, 3, 4, 5, 6] and cfg.gripper.dxl_id == 111
    assert all(j.table.torque_enable == 512 and j.table.center_tick == 0 for j in cfg.joints)  # P series
    assert cfg.shutdown == "hold"


def _data() -> dict:
    return yaml.safe_load(DEFAULT_ROBOT_CONFIG.read_text())


@pytest.mark.parametrize(("edit", "key"), [
    (lambda d: d.update(baudrat=57600), "<dict>"),
    (lambda d: d.update(baudrate=12345), "baudrate"),
    (lambda d: d.update(shutdown="drop"), "shutdown"),
    (lambda d: d["joints"]["robot1/joint2"].update(id=300), "robot1/joint2.id"),
    (lambda d: d["joints"]["robot1/joint2"].update(model="PH99"), "robot1/joint2.model"),
    (lambda d: d["joints"]["robot1/joint4"].update(direction=2), "robot1/joint4.direction"),
    (lambda d: d["joints"]["robot1/joint5"].update(limits=[1.0, -1.0]), "robot1/joint5.limits"),
    (lambda d: d["joints"]["robot1/joint1"].update(profile_velocity=-5), "robot1/joint1.profile_velocity"),
    (lambda d: d["joints"]["robot1/joint1"].update(speed=3), "robot1/joint1"),
    (lambda d: d["joints"].pop("robot1/joint6"), "joints"),
    (lambda d: d["joints"]["robot1/joint6"].update(id=111), "joints"),
    (lambda d: d.update(home=[0.0, 1.0]), "home"),
    (lambda d: d.update(settle_timeout_s=30.0), "settle_timeout_s"),  # bounded: a blocked joint pushes no longer
    (lambda d: d.update(settle_timeout_s=0), "settle_timeout_s"),
])
def test_bad_configurations_name_the_key(edit, key):
    d = copy.deepcopy(_data())
    edit(d)
    with pytest.raises(RobotConfigError) as e:
        robot_config_from_dict(d)
    assert e.value.code == "bad_robot_config"
    assert e.value.detail["key"] == key
    assert key in str(e.value)


def test_file_errors(tmp_path):
    with pytest.raises(RobotConfigError, match="cannot read"):
        load_robot_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("joints: [unclosed")
    with pytest.raises(RobotConfigError, match="not valid YAML"):
        load_robot_config(bad)


def test_overrides_and_a_custom_file(tmp_path):
    d = _data()
    d["joints"]["robot1/joint2"].update(direction=-1, offset=0.05)
    f = tmp_path / "arm.yaml"
    f.write_text(yaml.safe_dump(d))
    cfg = load_robot_config(f, port="/dev/ttyUSB3", baudrate=None)
    assert cfg.port == "/dev/ttyUSB3" and cfg.baudrate == 1_000_000
    assert cfg.joints[1].direction == -1 and cfg.joints[1].offset_rad == 0.05

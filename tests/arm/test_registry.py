"""The arm driver registry: backend name -> config class -> factory; a new backend is one folder + one line."""

from __future__ import annotations

import pytest

from common.errors import ServiceStartError
from common.launcher import ProcessSpec
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


def test_arm_options_are_typed_by_the_backend_and_a_wrong_one_names_the_valid_keys():
    entry = driver_entry("dynamixel")
    opts = entry.options({"baud": "57600", "emulate_bus": "true", "port": "/dev/ttyUSB3"})  # as --option gives them
    assert (opts.baud, opts.emulate_bus, opts.port, opts.robot_config) == (57600, True, "/dev/ttyUSB3", None)
    with pytest.raises(BadCommand) as e:
        entry.options({"prot": "/dev/ttyUSB0"})
    assert e.value.code == "unknown_option"
    assert e.value.detail["valid"] == ["baud", "emulate_bus", "port", "robot_config"]
    assert "arm backend dynamixel has no option prot" in e.value.message and "emulate_bus" in e.value.message
    for key, value in (("baud", "fast"), ("emulate_bus", "perhaps")):
        with pytest.raises(BadCommand) as e:
            entry.options({key: value})
        assert e.value.code == "bad_option" and e.value.detail["key"] == key
    with pytest.raises(BadCommand) as e:
        make_driver("sim", DriverContext(options={"session": "x"}))  # the twin's driver takes no option
    assert e.value.code == "unknown_option" and e.value.detail["valid"] == []


def test_the_robot_file_comes_from_its_environment_variable_unless_given(tmp_path, monkeypatch):
    entry = driver_entry("dynamixel")
    monkeypatch.setenv("OBJSCAN_ROBOT_CONFIG", str(tmp_path / "env.yaml"))
    assert entry.options({}).robot_config == str(tmp_path / "env.yaml")
    assert entry.options({"robot_config": "given.yaml"}).robot_config == "given.yaml"


def test_the_arm_service_refuses_an_unknown_option_at_start_with_its_valid_keys(service_group, tmp_path):
    with pytest.raises(ServiceStartError) as exc:
        service_group.launch([ProcessSpec("services.arm", ["--backend", "replay", "--option", f"folder={tmp_path}"],
                                          service="arm")], timeout=120)
    assert exc.value.code == "unknown_option", exc.value
    assert exc.value.detail["valid"] == ["session"] and "arm backend replay has no option folder" in exc.value.message


@pytest.mark.parametrize("command", ["scan", "up"])
def test_the_cli_hands_the_arm_service_options_its_registry_accepts(command):
    from argparse import Namespace

    from common.backend_options import option_pair
    from services.arm.drivers.dynamixel.robot_file import DEFAULT_ROBOT_CONFIG

    if command == "scan":
        from services.cli.cmd_scan import arm_args
    else:
        from services.cli.cmd_up import arm_args
    args = Namespace(emulate_bus=True, arm_backend=None, backend="sim", robot_config=str(DEFAULT_ROBOT_CONFIG))
    pairs = list(zip(*[iter(arm_args(args)["arm"])] * 2, strict=True))  # (flag, value): every flag takes one
    assert {flag for flag, _ in pairs} == {"--backend", "--option"}
    assert [value for flag, value in pairs if flag == "--backend"] == ["dynamixel"]
    opts = driver_entry("dynamixel").options(dict(option_pair(v) for flag, v in pairs if flag == "--option"))
    assert opts.emulate_bus and opts.robot_config == str(DEFAULT_ROBOT_CONFIG.resolve())

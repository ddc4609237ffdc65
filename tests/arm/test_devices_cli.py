"""``objscan devices``: servos found on a bus by broadcast ping (the emulated PAPRAS bus here)."""

from __future__ import annotations

import json

import yaml

from services.arm.drivers.dynamixel.robot_config import DEFAULT_ROBOT_CONFIG
from services.cli.main import main


def test_devices_lists_the_emulated_papras_bus(capsys):
    assert main(["devices", "--emulate-bus", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bus"] == "emulated"
    assert [(s["id"], s["model"]) for s in out["servos"]] == [
        (1, "PH54-200-S500-R"), (2, "PH54-200-S500-R"), (3, "PH54-100-S500-R"), (4, "PH54-100-S500-R"),
        (5, "PH42-020-S300-R"), (6, "PH42-020-S300-R"), (111, "RH-P12-RN(A)")]
    assert isinstance(out["cameras"], list)  # no camera on this machine: an empty list, not an error


def test_devices_names_a_missing_port(capsys):
    assert main(["devices", "--port", "/dev/objscan-no-such-port", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["error"]["code"] == "port_unavailable" and "/dev/objscan-no-such-port" in out["error"]["message"]


def test_up_refuses_a_bad_robot_config_before_starting_anything(tmp_path, capsys):
    data = yaml.safe_load(DEFAULT_ROBOT_CONFIG.read_text())
    data["joints"]["robot1/joint1"]["speed"] = 3  # not a key
    bad = tmp_path / "arm.yaml"
    bad.write_text(yaml.safe_dump(data))
    assert main(["up", "--robot-config", str(bad), "--port", "1", "--log-dir", str(tmp_path / "logs")]) == 2
    err = capsys.readouterr().err  # one line on stderr, like every command's failure
    assert "bad_robot_config" in err and "robot1/joint1" in err and "speed" in err
    assert not (tmp_path / "logs").exists()

"""``objscan devices``: servos found on a bus by broadcast ping (the emulated PAPRAS bus here)."""

from __future__ import annotations

import json

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

"""No container holds more than its job: devices, data mounts and privileges per compose service.

The compose files are read and merged the way ``docker compose`` does (tests/support/compose.py) for every
combination a lab runs: the twin, the real cell, each with and without the TLS override. Every grant a
service gets is checked against the table below; anything broader (another device, a USB bus, a cgroup
rule, a data folder mounted read-write by a service that only reads it, ``privileged``, a root ``user``,
a kept capability) fails. Before this table the camera container got ``/dev/bus/usb`` (every USB device,
the servo adapter included) and every container mounted ``./sessions`` and ``./models`` read-write.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.support import compose

REPO = Path(__file__).resolve().parents[2]
BASE = compose.load(REPO / "docker-compose.yml")
REAL = compose.load(REPO / "deploy" / "docker-compose.real.yml")
TLS = compose.load(REPO / "deploy" / "docker-compose.tls.yml")
UDEV = (REPO / "deploy" / "udev" / "99-objscan.rules").read_text()
ENV = {"OBJSCAN_DYNAMIXEL_DEVICE": "/dev/serial/by-id/usb-FTDI_U2D2-if00-port0",
       "OBJSCAN_ROBOT_CONFIG_FILE": "./config/robot.yaml"}
SERVO = f"{ENV['OBJSCAN_DYNAMIXEL_DEVICE']}:/dev/dynamixel"
INTEL_USB = "/dev/objscan-realsense"  # the udev-made mirror of /dev/bus/usb holding only vendor 8086 nodes

CELLS = {"twin": [BASE], "real": [BASE, REAL], "twin+tls": [BASE, TLS], "real+tls": [BASE, REAL, TLS]}


def _cell(name: str) -> dict[str, Any]:
    merged = CELLS[name][0]
    for over in CELLS[name][1:]:
        merged = compose.merge(merged, over)
    return compose.interpolate(merged, ENV)["services"]


def _mounts(svc: dict[str, Any]) -> dict[str, tuple[str, str]]:
    """container path -> (host source, "ro" | "rw") for every volume of a service, short or long syntax."""
    out = {}
    for v in svc.get("volumes", []):
        if isinstance(v, dict):
            out[v["target"]] = (str(v.get("source", "")), "ro" if v.get("read_only") else "rw")
        else:
            parts = str(v).split(":")
            mode = parts[2] if len(parts) > 2 else "rw"
            out[parts[1]] = (parts[0], "ro" if "ro" in mode.split(",") else "rw")
    return out


def _allowed_mounts(name: str, cell: str) -> dict[str, tuple[str, str]]:
    """What each service may mount: the folders it writes, read-write; its own config and keys, read-only."""
    allowed: dict[str, tuple[str, str]] = {}
    if name == "orchestrator":  # the only writer of sessions (journal, frames, recording) and the library
        allowed |= {"/data/sessions": ("./sessions", "rw"), "/data/models": ("./models", "rw")}
    if name == "sim":  # the user's object meshes: read, never written
        allowed |= {"/objects": ("./objects", "ro")}
    if "real" in cell and name == "camera":
        allowed |= {"/dev/bus/usb": (INTEL_USB, "rw"), "/config/calibration": ("./calibration", "ro")}
    if "real" in cell and name == "ros2":  # the ROS 2 face reads the hand-eye file for /tf_static
        allowed |= {"/config/calibration": ("./calibration", "ro")}
    if "real" in cell and name == "arm":
        allowed |= {"/config/robot.yaml": (ENV["OBJSCAN_ROBOT_CONFIG_FILE"], "ro")}
    if "tls" in cell:
        allowed |= {"/certs/ca.pem": ("./deploy/certs/ca.pem", "ro"),
                    f"/certs/{name}.pem": (f"./deploy/certs/{name}.pem", "ro"),
                    f"/certs/{name}.key": (f"./deploy/certs/{name}.key", "ro")}
    return allowed


def _allowed_devices(name: str, cell: str) -> tuple[list[str], list[str], list[str]]:
    """(devices, device_cgroup_rules, group_add) a service may have."""
    if "real" in cell and name == "arm":
        return [SERVO], [], ["dialout"]
    if "real" in cell and name == "camera":
        return [], ["c 189:* rmw"], ["plugdev"]
    return [], [], []


def _services(cell: str) -> list[tuple[str, dict[str, Any]]]:
    return [(n, s) for n, s in _cell(cell).items() if n != "zenoh-router"]


@pytest.mark.parametrize("cell", list(CELLS))
def test_each_service_mounts_only_what_it_writes(cell):
    for name, svc in _services(cell):
        mounts = _mounts(svc)
        allowed = _allowed_mounts(name, cell)
        assert mounts == {t: allowed[t] for t in mounts if t in allowed}, (name, mounts)
        extra = set(mounts) - set(allowed)
        assert not extra, f"{cell}: {name} mounts {sorted(extra)} beyond its job"
        data = {t for t in mounts if t.startswith("/data/")}
        assert not data or name == "orchestrator", f"{cell}: {name} mounts session or model data {data}"


@pytest.mark.parametrize("cell", list(CELLS))
def test_only_the_arm_sees_the_servo_and_the_camera_only_intel_usb(cell):
    for name, svc in _services(cell):
        devices, rules, groups = _allowed_devices(name, cell)
        assert list(svc.get("devices", [])) == devices, (cell, name, svc.get("devices"))
        assert list(svc.get("device_cgroup_rules", [])) == rules, (cell, name, svc.get("device_cgroup_rules"))
        assert list(svc.get("group_add", [])) == groups, (cell, name, svc.get("group_add"))
        for dev in svc.get("devices", []):  # never a whole bus, never /dev itself
            assert not re.match(r"^/dev(/bus/usb)?/?(:|$)", dev), (name, dev)
    if "real" in cell:
        cam = _cell(cell)["camera"]
        source = _mounts(cam)["/dev/bus/usb"][0]
        assert source == INTEL_USB and source != "/dev/bus/usb", source
        long_form = next(v for v in cam["volumes"] if isinstance(v, dict) and v["target"] == "/dev/bus/usb")
        assert long_form["bind"]["create_host_path"] is False  # no udev rules: the container is not created


def test_the_camera_usb_folder_holds_only_intel_devices():
    """The udev rule that fills the camera's USB folder matches Intel's vendor id only, and a removed device's
    node goes (no stale node is left for a later device to reuse)."""
    rules = [line for line in UDEV.splitlines() if INTEL_USB in line and not line.startswith("#")]
    adds = [r for r in rules if 'ACTION=="add"' in r]
    assert adds and all('ATTR{idVendor}=="8086"' in r and "mknod" in r for r in adds), adds
    assert all(re.findall(r'idVendor\}=="([0-9a-f]{4})"', r) == ["8086"] for r in adds)
    assert any('ACTION=="remove"' in r and "rm -f" in r for r in rules)


@pytest.mark.parametrize("cell", list(CELLS))
def test_no_service_is_privileged_or_root(cell):
    for name, svc in _services(cell):
        assert not svc.get("privileged"), name
        assert "ALL" in svc.get("cap_drop", []) and not svc.get("cap_add"), (name, svc.get("cap_add"))
        assert "no-new-privileges:true" in svc.get("security_opt", []), name
        user = str(svc.get("user", "")).split(":")[0]
        assert user not in ("root", "0"), (name, user)  # absent: the image's non-root USER
        for key in ("network_mode", "pid", "ipc", "userns_mode"):
            assert svc.get(key) != "host", (name, key)


def test_the_image_runs_as_a_non_root_user():
    text = (REPO / "Dockerfile").read_text()
    users = re.findall(r"^USER\s+(\S+)", text, flags=re.M)
    assert users, "the Dockerfile sets no USER: every service would run as root"
    last = users[-1].split(":")[0]
    assert last not in ("root", "0"), last
    assert text.index(f"USER {users[-1]}") < text.index("CMD")
    assert re.search(rf"useradd\b.*\b{re.escape(last)}\b", text)  # the user exists in the image

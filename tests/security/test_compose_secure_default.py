"""Secure-by-default compose and the real-cell override.

No docker engine here: the files are read and merged the way ``docker compose`` does
(tests/support/compose.py). Before the fix the router was published as ``7447:7447/tcp`` in plain TCP
(any host on the lab network could move the arm): ``test_plain_router_is_published_on_loopback_only``
failed on that file.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support import compose

REPO = Path(__file__).resolve().parents[2]
BASE = compose.load(REPO / "docker-compose.yml")
TLS = compose.load(REPO / "deploy" / "docker-compose.tls.yml")
REAL = compose.load(REPO / "deploy" / "docker-compose.real.yml")
REAL_ENV = {"OBJSCAN_DYNAMIXEL_DEVICE": "/dev/serial/by-id/usb-FTDI_U2D2-if00-port0",
            "OBJSCAN_ROBOT_CONFIG_FILE": "./config/robot.yaml"}


def _published(port: str) -> tuple[str, str]:
    """(host ip, host port) of a short-syntax port mapping; compose's default ip is every interface."""
    parts = port.split("/")[0].split(":")
    return (parts[0], parts[1]) if len(parts) == 3 else ("0.0.0.0", parts[0])


def test_plain_router_is_published_on_loopback_only():
    router = BASE["services"]["zenoh-router"]
    assert all(a.startswith("tcp/") for a in router["command"] if "/" in a)  # plain TCP inside the network
    assert router["ports"], "the router must be reachable from this box (the CLI)"
    for p in router["ports"]:
        assert _published(p)[0] == "127.0.0.1", f"plain-TCP router published beyond loopback: {p}"
    for name, svc in BASE["services"].items():
        assert not svc.get("ports") or name == "zenoh-router", f"{name} publishes ports"


def test_the_choice_is_explicit_in_the_file():
    text = (REPO / "docker-compose.yml").read_text()
    assert "LOOPBACK ONLY" in text and "deploy/docker-compose.tls.yml" in text


def test_tls_override_replaces_the_publication_with_a_tls_only_listener():
    merged = compose.merge(BASE, TLS)
    router = merged["services"]["zenoh-router"]
    assert isinstance(TLS["services"]["zenoh-router"]["ports"], compose.Override)  # replaces, not adds
    assert [_published(p) for p in router["ports"]] == [("0.0.0.0", "7447")]
    cfg = (REPO / "deploy" / "zenoh-router-tls.json5").read_text()
    listen = re.search(r"listen:\s*\{\s*endpoints:\s*\[([^\]]*)\]", cfg).group(1)
    assert re.findall(r'"([a-z]+)/', listen) == ["tls"], listen  # nothing plain on the published port
    assert re.search(r"enable_mtls:\s*true", cfg)
    for name, svc in merged["services"].items():
        if name != "zenoh-router":
            assert svc["environment"]["OBJSCAN_ZENOH_CONNECT"].startswith("tls/")


def test_real_cell_refuses_to_start_without_its_devices():
    for missing in REAL_ENV:
        env = {k: v for k, v in REAL_ENV.items() if k != missing}
        with pytest.raises(compose.ComposeInterpolationError, match=missing) as e:
            compose.interpolate(REAL, env)
        assert "docs/real-cell.md" in str(e.value)  # the message says where to look


def test_real_cell_merged():
    merged = compose.interpolate(compose.merge(BASE, REAL), REAL_ENV)
    s = merged["services"]
    assert "sim" not in compose.started_by_default(merged)  # the twin is off
    assert set(compose.started_by_default(merged)) == {"zenoh-router", "camera", "arm", "registration", "grasp",
                                                      "orchestrator"}
    cam, arm = s["camera"], s["arm"]
    assert cam["command"][cam["command"].index("--backend") + 1] == "realsense"
    assert not cam.get("devices")  # USB through the Intel-only folder (test_compose_least_privilege.py)
    assert arm["command"][arm["command"].index("--backend") + 1] == "dynamixel"
    options = [arm["command"][i + 1] for i, flag in enumerate(arm["command"]) if flag == "--option"]
    port = next(o.split("=", 1)[1] for o in options if o.startswith("port="))
    assert arm["devices"] == [f"{REAL_ENV['OBJSCAN_DYNAMIXEL_DEVICE']}:{port}"]
    # the robot configuration is a mounted file the arm service finds through OBJSCAN_ROBOT_CONFIG
    mount = next(v for v in arm["volumes"] if isinstance(v, dict) and v["target"] == "/config/robot.yaml")
    assert mount["source"] == REAL_ENV["OBJSCAN_ROBOT_CONFIG_FILE"] and mount["read_only"]
    assert mount["bind"]["create_host_path"] is False  # a missing file fails, never becomes an empty folder
    assert arm["environment"]["OBJSCAN_ROBOT_CONFIG"] == mount["target"]
    for svc in (cam, arm):  # a missing device stops after a few tries instead of restart-looping
        assert svc["restart"].startswith("on-failure")
        assert not {"/data/sessions", "/data/models"} & {compose._volume_target(v) for v in svc["volumes"]}
    # sessions are inside the volume: the orchestrator's root is the mounted folder
    orch = s["orchestrator"]["command"]
    assert orch[orch.index("--sessions") + 1] == "/data/sessions"
    assert "OBJSCAN_HAND_EYE" in cam["environment"]  # the calibration file the camera loads at start


@pytest.mark.parametrize("name", ["camera", "arm"])
def test_real_cell_commands_are_accepted_by_the_services(name):
    cmd = compose.interpolate(compose.merge(BASE, REAL), REAL_ENV)["services"][name]["command"]
    out = subprocess.run([sys.executable, "-m", *cmd[2:], "--help"], capture_output=True, text=True, timeout=120,
                         cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]


def test_camera_without_a_d435_fails_fast_with_a_clear_message(service_group):
    from common.launcher import ProcessSpec

    proc = service_group.start(ProcessSpec("services.camera", ["--backend", "realsense"], name="camera"))
    assert proc.wait(timeout=90) != 0
    log = (service_group.log_dir / "camera.log").read_text()
    assert "no RealSense camera is attached" in log, log[-2000:]

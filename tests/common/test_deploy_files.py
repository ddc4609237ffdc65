"""docker-compose.yml and the Dockerfile: no docker engine runs here, so check what can be checked.

Every service's command must resolve to a real entry point of the package that accepts the arguments
the compose file gives it, the router must be pinned to the Python package's zenoh minor version, and
every service must reach the router by name.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
COMPOSE = yaml.safe_load((REPO / "docker-compose.yml").read_text())


def _expand(arg: str) -> str:
    """Resolve ${VAR:-default} the way compose does when VAR is unset."""
    return re.sub(r"\$\{[A-Z_]+:-([^}]*)\}", r"\1", arg)


def test_router_is_pinned_to_the_python_zenoh_minor_version():
    image = COMPOSE["services"]["zenoh-router"]["image"]
    assert image.startswith("eclipse/zenoh:")
    tag = image.split(":")[1]
    assert tag.split(".")[:2] == version("eclipse-zenoh").split(".")[:2], (tag, version("eclipse-zenoh"))


SERVICES = [name for name in COMPOSE["services"] if name != "zenoh-router"]


def test_every_objscan_service_is_in_compose():
    assert set(SERVICES) == {"sim", "camera", "arm", "registration", "grasp", "orchestrator", "ros2"}


@pytest.mark.parametrize("name", SERVICES)
def test_service_command_resolves_to_a_real_entry_point(name):
    svc = COMPOSE["services"][name]
    cmd = [_expand(a) for a in svc["command"]]
    assert cmd[:2] == ["python", "-m"], cmd
    module = cmd[2]
    assert importlib.util.find_spec(f"{module}.__main__") is not None, f"{module} has no __main__"
    env = svc["environment"]
    assert env["OBJSCAN_ZENOH_CONNECT"] == "tcp/zenoh-router:7447" and env["OBJSCAN_ZENOH_MODE"] == "client"
    assert "zenoh-router" in svc["depends_on"]
    # the arguments compose passes are accepted by the service's own parser
    out = subprocess.run([sys.executable, "-m", module, *cmd[3:], "--help"], capture_output=True, text=True,
                         timeout=120, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    for flag in (a for a in cmd[3:] if a.startswith("--")):
        assert flag in out.stdout, f"{module} does not document {flag}"


def test_dockerfile_installs_the_locked_dependencies_and_the_system_libraries():
    text = (REPO / "Dockerfile").read_text()
    assert "requirements.lock" in text and "libusb-1.0-0" in text
    assert re.search(r"FROM python:3\.1[1-9]", text)

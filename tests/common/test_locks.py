"""Two locks: the runtime one (image, demo, install) carries no test tools; the development one adds them
on top of the very same runtime pins. Checked on the files, the way the scripts and the Dockerfile use them."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
# websockets (the Foxglove test's client) is in the test extra but not a tool: mujoco-studio needs it at run time
DEV_TOOLS = {"pytest", "pytest-timeout", "hypothesis", "ruff", "atheris"}  # trimesh: the export needs it at run time


def _pins(lock: str) -> dict[str, str]:
    text = (REPO / lock).read_text()
    return {m.group(1).lower(): m.group(2) for m in re.finditer(r"(?m)^([A-Za-z0-9_.\-]+)==(\S+)", text)}


def _name(req: str) -> str:
    return re.split(r"[<>=!~\[; ]", req, maxsplit=1)[0].lower()


def test_runtime_lock_has_every_runtime_dependency_and_no_test_tool():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    runtime = _pins("requirements.lock")
    assert {_name(r) for r in project["dependencies"]} <= set(runtime)
    assert not DEV_TOOLS & set(runtime), DEV_TOOLS & set(runtime)
    assert runtime["rerun-sdk"] == "0.41.0"


def test_dev_lock_adds_the_test_extra_on_the_same_runtime_pins():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    runtime, dev = _pins("requirements.lock"), _pins("requirements-dev.lock")
    assert {_name(r) for r in project["optional-dependencies"]["test"]} <= set(dev)
    assert {k: dev.get(k) for k in runtime} == runtime  # nothing the runtime pins moves in development


def test_scripts_and_image_install_the_right_lock():
    install = (REPO / "scripts/install.sh").read_text()
    assert "-r \"$lock\"" in install and "install_lock requirements.lock" in install
    assert "install_lock requirements-dev.lock" in install
    assert "bash scripts/install.sh --dev" in (REPO / "scripts/test.sh").read_text()
    demo = (REPO / "scripts/demo.sh").read_text()
    assert "bash scripts/install.sh\n" in demo and "--dev" not in demo
    docker = [ln for ln in (REPO / "Dockerfile").read_text().splitlines() if not ln.lstrip().startswith("#")]
    assert any("-r requirements.lock" in ln for ln in docker)
    assert not any("requirements-dev.lock" in ln for ln in docker)

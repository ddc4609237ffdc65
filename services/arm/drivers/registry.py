"""Arm driver registry: backend name -> its folder's ``DRIVER`` entry (config class + factory).

A new backend is one folder under ``drivers/`` whose ``__init__`` defines ``DRIVER = DriverEntry(...)``,
plus one line in ``BACKENDS``. Folders are imported only when chosen, so the sim cell never needs
dynamixel-sdk and a hardware backend never needs the twin.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from services.arm.drivers.base import ArmDriver
from services.arm.errors import BadCommand

BACKENDS: dict[str, str] = {
    "sim": "services.arm.drivers.sim",
    "dynamixel": "services.arm.drivers.dynamixel",
    "replay": "services.arm.drivers.replay",
}


@dataclass
class DriverContext:
    """What a factory may need from the service: its Zenoh session and robot name (to reach the twin),
    the kinematics (poses for the twin), and the command-line/environment options of the backend."""

    session: Any = None
    robot: str = "papras"
    kinematics: Any = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DriverEntry:
    """One backend: ``config_from_options(options) -> config`` (an instance of ``config_class``),
    ``factory(config, context) -> ArmDriver``; ``realtime``: stream set-points at wall-clock rate."""

    name: str
    config_class: type
    config_from_options: Callable[[dict[str, Any]], Any]
    factory: Callable[[Any, DriverContext], ArmDriver]
    realtime: bool = True
    description: str = ""


def driver_entry(name: str) -> DriverEntry:
    if name not in BACKENDS:
        raise BadCommand(f"unknown arm backend {name!r}", code="unknown_backend",
                         detail={"backend": name, "known": sorted(BACKENDS)})
    entry = importlib.import_module(BACKENDS[name]).DRIVER
    assert isinstance(entry, DriverEntry) and entry.name == name
    return entry


def make_driver(name: str, context: DriverContext) -> tuple[ArmDriver, DriverEntry]:
    """The backend ``name`` built from ``context.options``: (driver, its registry entry)."""
    entry = driver_entry(name)
    config = entry.config_from_options(context.options)
    return entry.factory(config, context), entry

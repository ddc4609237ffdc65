"""Arm driver registry: backend name -> its folder's ``DRIVER`` entry (config class + factory).

A new backend is one folder under ``drivers/`` whose ``__init__`` defines ``DRIVER = DriverEntry(...)``,
plus one line in ``BACKENDS``. Its options (``--option KEY=VALUE`` on the arm service) are the fields of its
options dataclass (``common/backend_options.py``): the registry parses them, the backend never sees a string.
Folders are imported only when chosen, so the sim cell never needs
dynamixel-sdk and a hardware backend never needs the twin.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from common.backend_options import parse_options
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
    the kinematics (poses for the twin), and the backend's options (``--option KEY=VALUE``; parsed by
    ``make_driver``, so a factory reads them typed)."""

    session: Any = None
    robot: str = "papras"
    kinematics: Any = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DriverEntry:
    """One backend: its options dataclass (``options_class``: ``--option`` keys, types, defaults, help),
    ``build_config(options) -> config`` (an instance of ``config_class``), ``factory(config, context) ->
    ArmDriver``; ``realtime``: stream set-points at wall-clock rate."""

    name: str
    config_class: type
    options_class: type
    build_config: Callable[[Any], Any]
    factory: Callable[[Any, DriverContext], ArmDriver]
    realtime: bool = True
    description: str = ""

    def options(self, given: Mapping[str, Any]) -> Any:
        """``given`` (``--option`` strings or typed values) as this backend's options; ``unknown_option`` /
        ``bad_option`` (``BadCommand``) name its valid keys."""
        return parse_options(self.options_class, given, backend=f"arm backend {self.name}", error=BadCommand)

    def config_from_options(self, given: Mapping[str, Any]) -> Any:
        """The backend's config from its options (parsed, then built)."""
        return self.build_config(self.options(given))


def driver_entry(name: str) -> DriverEntry:
    if name not in BACKENDS:
        raise BadCommand(f"unknown arm backend {name!r}", code="unknown_backend",
                         detail={"backend": name, "known": sorted(BACKENDS)})
    entry = importlib.import_module(BACKENDS[name]).DRIVER
    assert isinstance(entry, DriverEntry) and entry.name == name
    return entry


def make_driver(name: str, context: DriverContext) -> tuple[ArmDriver, DriverEntry]:
    """The backend ``name`` built from ``context.options``: (driver, its registry entry). The factory's
    context carries the options parsed (typed, defaults filled in)."""
    entry = driver_entry(name)
    options = entry.options(context.options)
    context = dataclasses.replace(context, options=dataclasses.asdict(options))
    return entry.factory(entry.build_config(options), context), entry

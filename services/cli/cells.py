"""Which processes make up a cell, and how the CLI joins an existing network or starts its own.

The embedded default is every service as its own OS process with the ``sim`` backends, wired through a
Zenoh router on loopback. Commands that need services (scan, replay, capture) reuse running ones when
``objscan status`` would find them, and start this set otherwise.
"""

from __future__ import annotations

import os

from common.launcher import ProcessSpec
from common.zenoh_config import ZenohSettings

SERVICE_MODULES = {
    "sim": "services.sim",
    "camera": "services.camera",
    "arm": "services.arm",
    "registration": "services.registration",
    "grasp": "services.grasp",
    "orchestrator": "services.orchestrator",
}


def cell_specs(services: list[str] | None = None, *, backend: str = "sim",
               extra_args: dict[str, list[str]] | None = None) -> list[ProcessSpec]:
    """Process specs for the named services (default: all), with the given hardware backend."""
    names = services or list(SERVICE_MODULES)
    specs = []
    for name in names:
        args = list((extra_args or {}).get(name, []))
        if name == "camera" or (name == "arm" and backend != "realsense"):
            args = ["--backend", backend, *args]
        specs.append(ProcessSpec(SERVICE_MODULES[name], args, service=name))
    return specs


def network_settings(connect: str | None) -> ZenohSettings:
    """Settings for the CLI's own session: ``--connect`` wins, then the environment, then loopback."""
    s = ZenohSettings.from_env()
    if connect:
        s = s.with_overrides(connect=[e for e in connect.split(",") if e])
    return s


def add_network_args(p) -> None:  # noqa: ANN001 - argparse parser
    p.add_argument("--connect", default=os.environ.get("OBJSCAN_ZENOH_CONNECT"),
                   help="zenoh endpoint(s) of the cell (default: env OBJSCAN_ZENOH_CONNECT or tcp/127.0.0.1:7447)")

"""Which processes make up a cell: one OS process per service, each with its hardware backend.

The embedded default is every service as its own process with the ``sim`` backends, wired through a Zenoh
router on loopback. The CLI (``objscan up``/``scan``), the benchmarks and the tests start cells from these
specs; it lives beside the service packages, not in the CLI, so the benchmarks do not import the CLI that
imports them.
"""

from __future__ import annotations

from common.launcher import ProcessSpec

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

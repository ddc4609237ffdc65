"""Which processes make up a cell: one OS process per service, each with its hardware backend.

The embedded default is every service as its own process with the ``sim`` backends, wired through a Zenoh
router on loopback. The CLI (``objscan up``/``scan``), the benchmarks and the tests start cells from these
specs; it lives beside the service packages, not in the CLI, so the benchmarks do not import the CLI that
imports them.
"""

from __future__ import annotations

from collections.abc import Mapping

from common.launcher import ProcessSpec

SERVICE_MODULES = {
    "sim": "services.sim",
    "camera": "services.camera",
    "arm": "services.arm",
    "registration": "services.registration",
    "grasp": "services.grasp",
    "orchestrator": "services.orchestrator",
}


CELLS: dict[str, dict[str, str]] = {
    "sim": {"arm": "sim", "camera": "sim"},
    "real": {"arm": "dynamixel", "camera": "realsense"},
    "replay": {"arm": "replay", "camera": "replay"},
}
"""Cell name (``--backend`` of ``objscan up``/``scan``/``calibrate``) -> the backend of each hardware
service, a name of its registry (``services/camera/registry.py``, ``services/arm/drivers/registry.py``)."""


def cell_backends(backend: str | Mapping[str, str]) -> dict[str, str]:
    """A cell name of ``CELLS``, or an explicit {service: backend} (e.g. ``{"camera": "png_folder"}``)."""
    if isinstance(backend, str):
        if backend not in CELLS:
            raise ValueError(f"unknown cell {backend!r}; choose one of {sorted(CELLS)}")
        return dict(CELLS[backend])
    return dict(backend)


def needs_twin(backend: str | Mapping[str, str]) -> bool:
    """Whether the cell's hardware is the digital twin (the ``sim`` service must run)."""
    return "sim" in cell_backends(backend).values()


def hardware_services(backend: str | Mapping[str, str]) -> list[str]:
    """The processes a cell's hardware needs: its backends' services, after the twin when it is simulated."""
    return (["sim"] if needs_twin(backend) else []) + list(cell_backends(backend))


def cell_specs(services: list[str] | None = None, *, backend: str | Mapping[str, str] = "sim",
               extra_args: dict[str, list[str]] | None = None) -> list[ProcessSpec]:
    """Process specs for the named services (default: all), with the given cell's hardware backends."""
    backends = cell_backends(backend)
    names = services or list(SERVICE_MODULES)
    specs = []
    for name in names:
        args = list((extra_args or {}).get(name, []))
        if name in backends:
            args = ["--backend", backends[name], *args]
        specs.append(ProcessSpec(SERVICE_MODULES[name], args, service=name))
    return specs

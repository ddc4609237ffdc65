"""Mass, centre of mass and inertia of the closed mesh, from a density or a given mass.

A solid of uniform density: the volume integrals of the closed mesh (trimesh's divergence-theorem mass
properties) give the volume, the centre of mass and the inertia tensor at unit density; a density scales
them, a given mass sets the density to mass / volume. Without either, the density of water (the HOPE
groceries are liquid-filled cartons and cans, 1000 kg/m^3 within their packaging's tolerance).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.export.errors import ExportError, ExportInputError

DEFAULT_DENSITY_KG_M3 = 1000.0


@dataclass(frozen=True)
class Inertial:
    """Solid-body properties in the object frame (SI): inertia about the centre of mass, frame axes."""

    mass: float
    density: float
    volume: float
    com: np.ndarray  # (3,)
    inertia: np.ndarray  # (3, 3) about the centre of mass

    def to_json(self) -> dict:
        return {"mass_kg": self.mass, "density_kg_m3": self.density, "volume_m3": self.volume,
                "com_m": self.com.tolist(), "inertia_kg_m2": self.inertia.tolist()}


def inertial(vertices: np.ndarray, triangles: np.ndarray, *, density: float | None = None,
             mass: float | None = None) -> Inertial:
    """The solid's ``Inertial`` for a density (kg/m^3) or a mass (kg), not both; a closed mesh is required."""
    import trimesh

    if density is not None and mass is not None:
        raise ExportInputError("give a density or a mass, not both", code="bad_argument",
                               detail={"density": density, "mass": mass})
    for name, value in (("density", density), ("mass", mass)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ExportInputError(f"{name} must be a positive number", code="bad_argument", detail={name: value})
    tm = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(triangles), process=False)
    props = tm.mass_properties  # at density 1
    volume = float(props["volume"])
    if not volume > 0:
        raise ExportError("the mesh encloses no positive volume", code="not_a_volume", detail={"volume": volume})
    rho = float(mass) / volume if mass is not None else float(density or DEFAULT_DENSITY_KG_M3)
    I = np.asarray(props["inertia"], float) * rho  # about the centre of mass, at the mesh axes
    I = 0.5 * (I + I.T)
    return Inertial(mass=rho * volume, density=rho, volume=volume, com=np.asarray(props["center_mass"], float),
                    inertia=I)

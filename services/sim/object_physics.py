"""Per-object physical values for the twin's MuJoCo mode: a ``<mesh>.physics.json`` beside a mesh file.

Why: the twin gives every object the same density (400 kg/m^3) and the same rubber-pad friction, so a
benchmark over generated shapes could not vary the two things that decide whether a grasp holds. The file
holds ``mass_kg`` (the object's mass; its inertia scales with it) and ``friction`` (the sliding friction of
its surface, against the pads and the table alike: MuJoCo takes the larger coefficient of a contact pair, so
both sides get it). Either key may be left out; without the file nothing changes.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from services.sim.errors import SimInputError
from services.sim.physics import PhysicsConfig

SUFFIX = ".physics.json"


def sidecar(mesh_path: str | Path) -> Path:
    """Where the physical values of the mesh at ``mesh_path`` are read from."""
    p = Path(mesh_path)
    return p.with_name(p.name + SUFFIX)


def physics_config_for(mesh_path: str, base: PhysicsConfig | None = None) -> PhysicsConfig | None:
    """``base`` (default values) with the mesh's mass and friction from its sidecar file; None without one."""
    path = sidecar(mesh_path)
    if not Path(mesh_path).is_file() or not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SimInputError(f"{path.name}: not readable JSON ({exc})", code="bad_value") from None
    if not isinstance(data, dict):
        raise SimInputError(f"{path.name}: must be a JSON object with mass_kg and/or friction", code="bad_value")
    cfg = base or PhysicsConfig()
    changes: dict[str, float] = {}
    for key, lo, hi in (("mass_kg", 0.001, 50.0), ("friction", 0.05, 3.0)):
        if key not in data:
            continue
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= float(v) <= hi:
            raise SimInputError(f"{path.name}: {key} must be a number in [{lo}, {hi}], got {v!r}",
                                code="bad_value", detail={key: str(v)[:40]})
        if key == "mass_kg":
            changes["mass"] = float(v)
        else:
            changes["pad_friction"] = changes["object_friction"] = float(v)
    return replace(cfg, **changes)

"""A mesh's ``.physics.json`` sets the twin's mass and friction for it (MuJoCo mode); bad values are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("mujoco")
trimesh = pytest.importorskip("trimesh")

from services.sim.errors import SimInputError  # noqa: E402
from services.sim.object_physics import physics_config_for, sidecar  # noqa: E402
from services.sim.physics import PhysicsConfig  # noqa: E402
from services.sim.world import World  # noqa: E402


def _box(folder, **values):  # noqa: ANN001, ANN202
    folder.mkdir(parents=True, exist_ok=True)
    mesh = trimesh.creation.box(extents=(0.06, 0.06, 0.10))
    mesh.apply_translation((0, 0, 0.05))
    path = folder / "box.ply"
    mesh.export(path)
    if values:
        sidecar(path).write_text(json.dumps(values))
    return path


def test_the_sidecar_sets_mass_and_friction(tmp_path):
    path = _box(tmp_path, mass_kg=0.7, friction=0.4)
    world = World(str(path), physics="mujoco")
    assert world._physics.mass == pytest.approx(0.7, rel=1e-6)
    friction = world._physics.model.geom_friction[:, 0]
    assert np.all(np.isclose(friction, 0.4))  # the pads, the object and the table
    plain = World(str(_box(tmp_path / "plain")), physics="mujoco")  # no sidecar: density x volume
    assert plain._physics.mass == pytest.approx(400.0 * 0.06 * 0.06 * 0.10, rel=0.05)


def test_bad_sidecar_values_are_refused(tmp_path):
    path = _box(tmp_path, mass_kg=-1)
    with pytest.raises(SimInputError, match="mass_kg"):
        physics_config_for(str(path))
    sidecar(path).write_text("not json")
    with pytest.raises(SimInputError, match="JSON"):
        physics_config_for(str(path))
    assert physics_config_for(str(tmp_path / "missing.ply")) is None
    assert physics_config_for(str(_box(tmp_path / "plain"))) is None
    assert PhysicsConfig().mass == 0.0

"""The planner on real object shapes: HOPE meshes (shared data) seen from the three scan positions."""

from __future__ import annotations

import numpy as np
import pytest

from services.grasp import plan_grasps
from services.grasp.collision import table_box
from tests.conftest import shared_data

UP = np.array([0.0, 0.0, 1.0])


@pytest.mark.parametrize("name", ["milk", "tomato_sauce"])
def test_hope_partial_views_get_valid_frontal_grasps(name):
    shared_data("hope", name)
    from bench.grasp import OBJECT_XY, _mesh_clouds, _table

    p, n = _mesh_clouds([name], seed=0, dense_points=60_000)[name]
    plan = plan_grasps(p, n, _table())
    assert plan.grasps, plan.explain()
    g = plan.grasps[0]
    assert g.kind == "frontal" and 0.05 < g.width < 0.106  # both are ~6.6-7.4 cm across
    line = (g.contacts[0] - g.contacts[1]) / g.width
    # estimated normals at the contacts agree with the grasp line (antipodal)
    for c in g.contacts:
        near = np.argsort(((p - c) ** 2).sum(axis=1))[:15]
        avg = np.abs(n[near] @ line).mean()
        assert avg > np.cos(np.radians(25))
    # the grasp height is inside the object's vertical range and the hand stays off the table
    assert 0.0 < g.metrics["contact_height"] < p[:, 2].max()
    table = table_box(p, UP, 0.0, 0.5, 0.025)
    for box in g.collision_boxes.values():
        assert (box.corners() @ UP).min() > (table.corners() @ UP).max()
    # the turn keeps the footprint centre of the mesh (placed at OBJECT_XY) within 3 mm
    assert np.linalg.norm(plan.object_center[:2] - OBJECT_XY) < 0.003

"""Oriented boxes: the separating-axis test against coal, containment, and the table-aligned box."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from services.grasp.boxes import (
    OrientedBox,
    boxes_overlap,
    min_area_rectangle,
    points_in_box,
    table_aligned_box,
)
from tests.grasp import shapes as S


def _coal_verdict(a: OrientedBox, b: OrientedBox) -> tuple[bool, float]:
    coal = pytest.importorskip("coal")

    def obj(box: OrientedBox):
        return coal.CollisionObject(coal.Box(*(2 * box.half_extents)),
                                    coal.Transform3s(box.rotation, box.center))

    req, res = coal.CollisionRequest(), coal.CollisionResult()
    hit = coal.collide(obj(a), obj(b), req, res) > 0
    dreq, dres = coal.DistanceRequest(), coal.DistanceResult()
    dist = coal.distance(obj(a), obj(b), dreq, dres)
    return hit, float(dist)


def _random_box(rng: np.random.Generator) -> OrientedBox:
    return OrientedBox(rng.uniform(-0.1, 0.1, 3), Rotation.random(random_state=rng).as_matrix(),
                       rng.uniform(0.005, 0.08, 3))


def test_sat_agrees_with_coal_on_random_boxes():
    rng = np.random.default_rng(7)
    checked = hits = 0
    for _ in range(400):
        a, b = _random_box(rng), _random_box(rng)
        coal_hit, dist = _coal_verdict(a, b)
        if abs(dist) < 1e-5:  # touching within tolerance: either answer is right
            continue
        assert boxes_overlap(a, b) == coal_hit, (a, b, dist)
        assert boxes_overlap(b, a) == coal_hit
        checked += 1
        hits += coal_hit
    assert checked > 350 and 50 < hits < checked - 50  # both verdicts well represented


def test_sat_needs_edge_edge_axes():
    # Two long thin boxes crossed like an X in plan, offset in height by more than their thickness
    # along the face normals' blind spot: only an edge-edge axis separates them.
    R = Rotation.from_euler("z", 45, degrees=True).as_matrix() @ Rotation.from_euler("x", 45, degrees=True).as_matrix()
    a = OrientedBox(np.zeros(3), np.eye(3), np.array([0.1, 0.01, 0.01]))
    b = OrientedBox(np.array([0.0, 0.0, 0.0]), R, np.array([0.01, 0.1, 0.01]))
    assert boxes_overlap(a, b)
    coal_hit, _ = _coal_verdict(a, b)
    assert coal_hit
    for dz in np.linspace(0.0, 0.06, 61):
        b2 = OrientedBox(np.array([0.0, 0.0, dz]), R, b.half_extents)
        hit, dist = _coal_verdict(a, b2)
        if abs(dist) > 1e-5:
            assert boxes_overlap(a, b2) == hit, dz


def test_points_in_box_respects_orientation():
    R = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    box = OrientedBox(np.array([1.0, 2.0, 0.5]), R, np.array([0.2, 0.05, 0.1]))
    inside = box.center + R @ np.array([0.19, 0.04, -0.09])
    outside_local_y = box.center + R @ np.array([0.0, 0.06, 0.0])
    outside_world_y = box.center + np.array([0.0, 0.19, 0.0])  # inside the unrotated box, not this one
    mask = points_in_box(box, np.array([inside, outside_local_y, outside_world_y]))
    assert mask.tolist() == [True, False, False]


@pytest.mark.parametrize("angle_deg", [0.0, 17.0, 45.0, 80.0])
def test_min_area_rectangle_recovers_a_rotated_rectangle(angle_deg):
    rng = np.random.default_rng(1)
    local = rng.uniform([-0.05, -0.02], [0.05, 0.02], (5000, 2))
    a = np.radians(angle_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    xy = local @ R.T + [0.3, -0.1]
    center, axes, sides = min_area_rectangle(xy)
    assert np.allclose(sorted(sides), [0.04, 0.1], atol=1e-3)
    long_axis = axes[:, int(np.argmax(sides))]
    assert abs(long_axis @ R[:, 0]) > np.cos(np.radians(0.5))
    assert np.allclose(center, [0.3, -0.1], atol=1e-3)


def test_table_aligned_box_of_a_yawed_carton_follows_its_sides():
    p, _ = S.milk_carton(yaw_deg=25.0, view_from=S.scan_cameras())
    box = table_aligned_box(p, np.array([0.0, 0.0, 1.0]))
    assert np.allclose(box.rotation[:, 0], [0, 0, 1])
    yaw_axis = np.array([np.cos(np.radians(25)), np.sin(np.radians(25)), 0.0])
    assert max(abs(box.rotation[:, 1] @ yaw_axis), abs(box.rotation[:, 2] @ yaw_axis)) > np.cos(np.radians(1))
    assert np.allclose(np.sort(2 * box.half_extents), [0.07, 0.07, 0.19], atol=2e-3)
    assert abs(np.linalg.det(box.rotation) - 1.0) < 1e-9

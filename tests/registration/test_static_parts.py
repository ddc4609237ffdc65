"""Unit tests of the pieces of static registration on synthetic geometry with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import make_transform, rotation_about_axis
from common.messages import Plane
from services.registration.static import NoTableError
from services.registration.static.isolate import footprint_centre
from services.registration.static.table import segment_table


def test_footprint_centre_of_a_rotated_box():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.05, -0.02, 0.0], [0.05, 0.02, 0.12], (3000, 3))
    pts = pts @ rotation_about_axis([0, 0, 1], 0.5).T + [0.3, 0.1, 0.0]
    plane = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3))
    centre, height = footprint_centre(pts, plane)
    np.testing.assert_allclose(centre, [0.3, 0.1, 0.0], atol=1e-3)
    assert height == pytest.approx(0.12, abs=2e-3)


def _table_with_box(T: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(1)
    table = np.column_stack([rng.uniform(-0.3, 0.3, (6000, 2)), rng.normal(0, 0.0005, 6000)])
    box = rng.uniform([-0.03, -0.03, 0.0], [0.03, 0.03, 0.1], (1500, 3))
    pts = np.concatenate([table, box])
    return pts @ T[:3, :3].T + T[:3, 3]


def test_table_normal_faces_the_camera_and_offset_is_exact():
    T = make_transform(rotation_about_axis([1, 0.3, 0], 0.2), [0.0, 0.0, 0.05])
    pts = _table_with_box(T)
    up = T[:3, 2]
    for viewpoint in (T[:3, 3] + 0.5 * up, T[:3, 3] - 0.5 * up):
        fit = segment_table(pts, viewpoint=viewpoint, distance=0.004, iterations=300, seed=0, voxel=0.005)
        sign = 1.0 if viewpoint @ up > T[:3, 3] @ up else -1.0
        np.testing.assert_allclose(fit.plane.normal, sign * up, atol=2e-3)
        assert abs(fit.plane.signed_distance(T[:3, 3][None])[0]) < 5e-4  # the plane passes through the table
        assert fit.fraction > 0.7


def test_tilted_or_small_planes_are_not_a_table():
    pts = _table_with_box(np.eye(4))
    with pytest.raises(NoTableError) as exc:  # a wall: the plane is 90 degrees from the expected up
        segment_table(
            pts,
            viewpoint=np.array([0, 0, 1.0]),
            distance=0.004,
            iterations=300,
            seed=0,
            expected_up=np.array([1.0, 0.0, 0.0]),
        )
    assert exc.value.code == "no_table"
    rng = np.random.default_rng(2)
    blob = rng.normal(size=(3000, 3))
    blob = 0.05 * blob / np.linalg.norm(blob, axis=1, keepdims=True)  # a sphere has no dominant plane
    with pytest.raises(NoTableError):
        segment_table(blob, viewpoint=np.array([0, 0, 1.0]), distance=0.002, iterations=300, seed=0)

"""Isolation of an object standing on a turntable or platform: a support surface above the table plane.

The scene is built from points (no rendering): the table at z = 0, a turntable whose top (a disk at 13 cm)
overhangs its base so that the base and the top are apart at the clustering distance, and a box standing on the
top. The camera looks at the box, so the seed is on the box's front face.
"""

from __future__ import annotations

import numpy as np

from common.messages import Plane
from services.registration.static import StaticConfig
from services.registration.static.isolate import isolate_object, support_surface

CFG = StaticConfig()
STEP = 0.002  # m, like the scene cloud's voxel
TOP = 0.13  # m, the turntable's top above the table
BOX = (0.10, 0.10, 0.15)  # m, standing on it


def _grid(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return uu.ravel(), vv.ravel()


def _turntable(body_top: float = 0.10) -> np.ndarray:
    """The base (a cylinder's front half, r = 12 cm, up to ``body_top``) and the top (a disk, r = 16 cm, and its
    1 cm rim)."""
    a, z = _grid(np.linspace(np.pi / 2, 3 * np.pi / 2, 190), np.arange(0.006, body_top, STEP))
    base = np.column_stack([0.12 * np.cos(a), 0.12 * np.sin(a), z])
    x, y = _grid(np.arange(-0.16, 0.16, STEP), np.arange(-0.16, 0.16, STEP))
    disk = np.column_stack([x, y, np.full_like(x, TOP)])[np.hypot(x, y) <= 0.16]
    a, z = _grid(np.linspace(np.pi / 2, 3 * np.pi / 2, 250), np.arange(TOP - 0.01, TOP, STEP))
    rim = np.column_stack([0.16 * np.cos(a), 0.16 * np.sin(a), z])
    return np.concatenate([base, disk, rim])


def _box(bottom: float) -> np.ndarray:
    """The faces of a box a camera on -x sees: front (x = -w/2), side (y = -d/2) and top."""
    w, d, h = BOX
    y, z = _grid(np.arange(-d / 2, d / 2, STEP), np.arange(bottom, bottom + h, STEP))
    front = np.column_stack([np.full_like(y, -w / 2), y, z])
    x, z = _grid(np.arange(-w / 2, w / 2, STEP), np.arange(bottom, bottom + h, STEP))
    side = np.column_stack([x, np.full_like(x, -d / 2), z])
    x, y = _grid(np.arange(-w / 2, w / 2, STEP), np.arange(-d / 2, d / 2, STEP))
    top = np.column_stack([x, y, np.full_like(x, bottom + h)])
    return np.concatenate([front, side, top])


TABLE = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=np.zeros(3))
CAMERA = np.array([-0.8, 0.0, 0.5])


def _isolate(points: np.ndarray, seed: np.ndarray):
    ray = seed - CAMERA
    return isolate_object(points, TABLE, seed_point=seed, ray_origin=CAMERA, ray_dir=ray / np.linalg.norm(ray),
                          clearance=CFG.table_clearance, max_height=CFG.max_object_height,
                          cluster_voxel=CFG.cluster_voxel, eps=CFG.dbscan_eps, min_points=CFG.dbscan_min_points,
                          min_object_points=CFG.min_object_points, select_by=CFG.select_by,
                          max_support_gap=CFG.max_support_gap)


def test_an_object_on_a_turntable_is_isolated_on_the_turntables_top():
    box = _box(TOP)
    points = np.concatenate([_turntable(), box])
    is_box = np.arange(len(points)) >= len(points) - len(box)
    seed = np.array([-BOX[0] / 2, 0.0, TOP + BOX[2] / 2])  # the centre pixel: the box's front face
    iso = _isolate(points, seed)
    # the box and nothing else: not the turntable's base, not its top around the box
    assert iso.mask[~is_box].sum() == 0, points[iso.mask & ~is_box][:5]
    # all of the box but its bottom row (within the clearance of the top, like an object's on the table)
    assert iso.mask[is_box & (points[:, 2] > TOP + CFG.table_clearance)].mean() > 0.99
    assert iso.support is not None
    assert abs(-iso.support.offset - TOP) < 0.003  # the plane the box stands on, parallel to the table
    np.testing.assert_allclose(iso.support.normal, TABLE.normal)


def test_a_floating_cluster_without_a_face_to_stand_on_is_not_the_object():
    """An arm or a shelf edge hanging over the table near where the camera looks is still no object: the object
    standing on the table beside it is chosen."""
    # a vertical pole (the arm's forearm) hanging 5 cm above the table, where the camera looks
    a, z = _grid(np.linspace(0, 2 * np.pi, 60), np.arange(0.05, 0.3, STEP))
    pole = np.column_stack([0.03 * np.cos(a), 0.03 * np.sin(a), z])
    box = _box(0.0) + np.array([0.0, 0.2, 0.0])  # a box on the table, 20 cm aside
    points = np.concatenate([pole, box])
    iso = _isolate(points, np.array([-0.03, 0.0, 0.15]))
    assert iso.mask[len(pole):].mean() > 0.95 and not iso.mask[: len(pole)].any()
    assert getattr(iso, "support", None) is None


def test_the_support_is_the_lowest_horizontal_face_not_the_objects_top():
    points = np.concatenate([_turntable()[-20000:], _box(TOP)])  # top, rim and the box
    plane = support_surface(points[::2], TABLE, min_points=CFG.min_object_points, distance=CFG.table_clearance)
    assert plane is not None and abs(-plane.offset - TOP) < 0.003


def test_a_cluster_with_no_horizontal_face_has_no_support():
    a, z = _grid(np.linspace(0, 2 * np.pi, 60), np.arange(0.05, 0.3, 0.004))
    pole = np.column_stack([0.03 * np.cos(a), 0.03 * np.sin(a), z])
    assert support_surface(pole, TABLE, min_points=CFG.min_object_points, distance=CFG.table_clearance) is None

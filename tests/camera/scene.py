"""Ground truth for the camera tests: a box in front of a wall, ray-cast with Open3D for any pinhole camera.

The world frame is the D435 depth (left imager) optical frame: z forward, x right, y down. The wall is
fronto-parallel at ``WALL_Z``; the box's front face is at ``BOX_Z``. Rendering the same scene for the
depth imager and for the color camera gives both the frames to inject into a software D435 and the depth
that a correct depth-to-color alignment must produce.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from common.messages import Intrinsics

WALL_Z = 1.0
BOX_Z = 0.6
BOX_COLOR = (220, 30, 30)
WALL_COLOR = (90, 90, 90)


def _scene() -> tuple[o3d.t.geometry.RaycastingScene, int, int]:
    scene = o3d.t.geometry.RaycastingScene()
    wall = o3d.geometry.TriangleMesh.create_box(4.0, 4.0, 0.01).translate((-2.0, -2.0, WALL_Z))
    box = o3d.geometry.TriangleMesh.create_box(0.16, 0.12, 0.1).translate((-0.05, -0.04, BOX_Z))
    wall_id = scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(wall))
    box_id = scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(box))
    return scene, wall_id, box_id


def render(intr: Intrinsics, T_cam_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z-depth in metres, 0 where nothing is hit; RGB uint8 with the box red and the wall gray)."""
    scene, wall_id, box_id = _scene()
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        o3d.core.Tensor(intr.K), o3d.core.Tensor(np.asarray(T_cam_world, dtype=np.float64)),
        intr.width, intr.height)
    hit = scene.cast_rays(rays)
    t_hit = hit["t_hit"].numpy()  # rays have z = 1 in the camera frame, so t_hit is the z-depth
    ids = hit["geometry_ids"].numpy()
    depth = np.where(np.isfinite(t_hit), t_hit, 0.0)
    color = np.zeros((intr.height, intr.width, 3), np.uint8)
    color[ids == wall_id] = WALL_COLOR
    color[ids == box_id] = BOX_COLOR
    return depth, color


def to_units(depth_m: np.ndarray, depth_scale: float) -> np.ndarray:
    return np.round(depth_m / depth_scale).astype(np.uint16)

"""A small session folder made without the twin: a coloured box on a table, scanned from a ring of cameras.

The export reads only files (model.ply, report.json, view.json, the scans), so a ray-cast session exercises
it end to end in seconds. The box stands at a known pose with a known yaw, so the object frame, the volume
and the inertia have exact answers; ``T_base_object_true`` rides along as the twin records it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import open3d as o3d

from common.geometry import look_at
from common.messages import RGBDFrame, d435_intrinsics
from common.session_folder import write_scan, write_session

FACE_COLOURS = np.array([[200, 40, 40], [40, 200, 40], [40, 40, 200], [200, 200, 40], [200, 40, 200],
                         [40, 200, 200]], dtype=np.uint8)


def box_mesh(size: tuple[float, float, float]) -> o3d.geometry.TriangleMesh:
    """A box in its object frame: footprint centre at the origin, z up."""
    sx, sy, sz = size
    box = o3d.geometry.TriangleMesh.create_box(sx, sy, sz)
    box.translate((-sx / 2, -sy / 2, 0.0))
    return box


def make_box_session(root: Path, size: tuple[float, float, float] = (0.08, 0.05, 0.12),
                     position: tuple[float, float] = (0.55, 0.03), yaw_deg: float = 20.0,
                     cameras: int = 8, width: int = 160, height: int = 120) -> tuple[Path, np.ndarray]:
    """Write the session into ``root``; returns (session path, true T_base_object)."""
    root = Path(root)
    yaw = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    T[:2, 3] = position
    box = box_mesh(size)
    box.transform(T)
    scene = o3d.t.geometry.RaycastingScene()
    box_id = scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(box))
    table = o3d.geometry.TriangleMesh.create_box(2.0, 2.0, 0.01)
    table.translate((-0.5, -1.0, -0.01))
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(table))
    intr = d435_intrinsics(width, height)
    centre = np.array([position[0], position[1], size[2] / 2])
    poses = []
    for k in range(cameras):
        a = 2 * np.pi * k / cameras
        h = 0.25 if k % 2 else 0.15
        eye = centre + np.array([0.35 * np.cos(a), 0.35 * np.sin(a), h])
        poses.append(look_at(eye, centre))
    # one view, all scans in it: the model is view 0's base
    write_session(root, {"object": "synthetic_box", "profile": "ideal",
                         "views": [{"index": 0, "commanded_turn_deg": 0.0}]})
    xyz_all, rgb_all = [], []
    for j, Tc in enumerate(poses):
        depth, colour, pts, cols = _render(scene, box_id, Tc, intr, box)
        frame = RGBDFrame(color=colour, depth=depth, depth_scale=0.001, intrinsics=intr, T_base_camera=Tc,
                          T_base_camera_true=Tc)
        write_scan(root, 0, j, frame, {"T_base_object_true": T.tolist()})
        xyz_all.append(pts)
        rgb_all.append(cols)
    xyz = np.vstack(xyz_all)
    rgb = np.vstack(rgb_all)
    keep = xyz[:, 2] > 0.004  # the static stage cuts the table band
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz[keep]))
    pcd.colors = o3d.utility.Vector3dVector(rgb[keep] / 255.0)
    pcd = pcd.voxel_down_sample(0.002)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.006, max_nn=30))
    o3d.io.write_point_cloud(str(root / "model.ply"), pcd)
    (root / "view_00" / "view.json").write_text(json.dumps({
        "view": 0, "center": centre.tolist(), "height": size[2],
        "table": {"normal": [0.0, 0.0, 1.0], "offset": 0.0, "center": [position[0], position[1], 0.0]},
        "scan_poses": [p.tolist() for p in poses], "figures": {}}))
    (root / "report.json").write_text(json.dumps({"model_figures": {"T_model_view": [np.eye(4).tolist()]}}))
    return root, T


def _render(scene, box_id, T_base_camera, intr, box):  # noqa: ANN001, ANN202
    """Depth (uint16 mm), colour, and the box's hit points (base) with their face colours."""
    K = o3d.core.Tensor(intr.K, dtype=o3d.core.float64)
    extr = o3d.core.Tensor(np.linalg.inv(T_base_camera), dtype=o3d.core.float64)
    rays = scene.create_rays_pinhole(K, extr, intr.width, intr.height)
    hit = scene.cast_rays(rays)
    t = hit["t_hit"].numpy()
    geom = hit["geometry_ids"].numpy()
    prim = hit["primitive_ids"].numpy()
    r = rays.numpy()
    t = np.where(np.isfinite(t), t, 0.0)  # a ray that misses everything: no depth
    pts = r[..., :3] + r[..., 3:] * t[..., None]
    cam = (np.linalg.inv(T_base_camera) @ np.c_[pts.reshape(-1, 3), np.ones(pts.shape[0] * pts.shape[1])].T).T
    z = np.where(t > 0, cam[:, 2].reshape(t.shape), np.nan)
    depth = np.where(np.isfinite(z), np.round(z * 1000.0), 0).astype(np.uint16)
    colour = np.full(t.shape + (3,), 150, dtype=np.uint8)
    on_box = (geom == box_id) & (t > 0)
    face = prim[on_box] // 2  # create_box: two triangles per face
    colour[on_box] = FACE_COLOURS[face % 6]
    return depth, colour, pts[on_box].astype(np.float64), colour[on_box]

"""A closed surface from the registered views, in the object frame.

Two ways, both closed at the bottom by the footprint cap (``cap.py``) and meshed by screened Poisson:

- ``poisson``: the point model itself (its points, normals and colours), the cap points added. The model is
  the registration's output, already cleaned of outliers and fused at 1 mm.
- ``tsdf``: the session's RGB-D frames fused into a truncated signed distance volume at their registered
  poses; its zero crossing (points with normals and colours, the table cut away) replaces the model's
  points. It averages the raw depth of every scan, so noise and the registration's residuals both show.

Poisson closes what it is given: with the cap supporting the bottom, the surface needs no trimming of
low-density regions except far from every input point (``trim_far``), the islands it leaves are dropped
and non-manifold parts removed, and the bottom flattened onto the table plane (``cap.flatten_bottom``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from common.geometry import invert, rotate_vectors, transform_points
from services.export.cap import cap_points, flatten_bottom, footprint_outline
from services.export.errors import ExportError
from services.export.inputs import PosedFrame
from services.export.orient import orient_outward

METHODS = ("poisson", "tsdf")
#: Points closer to the table than this (m) are the table's, not the object's (the static stage's own cut).
TABLE_CUT_M = 0.004


@dataclass(frozen=True)
class SurfaceConfig:
    """Knobs of the surface step; the defaults are the ones measured on the HOPE sessions (docs/export.md)."""

    poisson_depth: int = 7
    cap_spacing_m: float = 0.002
    trim_far_m: float = 0.015  # vertices farther than this from every input point are Poisson's guesses
    target_triangles: int = 20000  # decimated to about this many (texture atlas and file size)
    tsdf_voxel_m: float = 0.0015
    tsdf_trunc_m: float = 0.006
    tsdf_depth_max_m: float = 1.0


def poisson_surface(xyz: np.ndarray, normals: np.ndarray, rgb: np.ndarray | None,
                    config: SurfaceConfig = SurfaceConfig(), *, oriented: bool = False) -> o3d.geometry.TriangleMesh:
    """Closed mesh (object frame) of object-frame points, the footprint cap added.

    ``oriented``: the normals already point outward (turned towards the scans, or a TSDF's gradient); else
    they are turned away from the object's vertical axis (``orient.orient_outward``).
    """
    keep = xyz[:, 2] > TABLE_CUT_M * 0.5
    xyz, normals = xyz[keep], normals[keep]
    rgb = None if rgb is None else rgb[keep]
    cap_xyz, cap_n = cap_points(footprint_outline(xyz), config.cap_spacing_m)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack([xyz, cap_xyz])))
    pcd.normals = o3d.utility.Vector3dVector(np.vstack([normals if oriented else orient_outward(xyz, normals), cap_n]))
    if rgb is not None:
        # the cap is unseen: it takes the colour of the nearest seen point (the base's lowest band)
        near = cKDTree(xyz).query(cap_xyz)[1]
        colours = np.vstack([rgb, rgb[near]]).astype(np.float64) / 255.0
        pcd.colors = o3d.utility.Vector3dVector(colours)
    # one thread: the parallel solve sums in a varying order, and the same session gave a different mesh on
    # every run (and CoACD's parts of it differed by millimetres and by seconds); on one thread it took
    # the same CPU time (1.2 s on the milk carton)
    mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pcd, depth=config.poisson_depth, scale=1.1, linear_fit=False, n_threads=1)
    mesh = _trim_far(mesh, np.asarray(pcd.points), config.trim_far_m)
    mesh = clean(mesh)
    if config.target_triangles and len(mesh.triangles) > config.target_triangles:
        mesh = clean(mesh.simplify_quadric_decimation(config.target_triangles))
    mesh = close_holes(mesh)
    mesh.vertices = o3d.utility.Vector3dVector(flatten_bottom(np.asarray(mesh.vertices)))
    mesh.compute_vertex_normals()
    return mesh


def _trim_far(mesh: o3d.geometry.TriangleMesh, points: np.ndarray, far_m: float) -> o3d.geometry.TriangleMesh:
    """Drop the parts of the Poisson surface far from every input point (its extrapolation at the box edge).

    Only whole connected pieces far away are dropped (``clean`` keeps the largest component afterwards):
    removing single far vertices of the object's own surface would open holes in it.
    """
    v = np.asarray(mesh.vertices)
    d = cKDTree(points).query(v, distance_upper_bound=far_m)[0]
    far = ~np.isfinite(d)
    if far.any():
        mesh.remove_vertices_by_mask(far)
    return mesh


def clean(mesh: o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    """Largest connected component, without duplicated, degenerate or non-manifold parts."""
    mesh.remove_duplicated_vertices()
    mesh.remove_duplicated_triangles()
    mesh.remove_degenerate_triangles()
    mesh.remove_non_manifold_edges()
    if len(mesh.triangles) == 0:
        raise ExportError("the surface reconstruction produced no triangles", code="no_surface")
    labels, counts, _ = mesh.cluster_connected_triangles()
    labels = np.asarray(labels)
    mesh.remove_triangles_by_mask(labels != int(np.argmax(np.asarray(counts))))
    mesh.remove_unreferenced_vertices()
    return mesh


def boundary_loops(triangles: np.ndarray) -> list[list[int]] | None:
    """The mesh's holes as vertex loops, each in the order a triangle closing it must follow; None when a
    boundary vertex has more than one way on (two holes touching at a vertex: not simple loops).

    A boundary edge is a directed edge a -> b of one triangle whose reverse b -> a no triangle has; the hole
    behind it is walked b -> a, so triangles (b, a, c) added along the loop keep the winding consistent.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    have = {(int(a), int(b)) for a, b in edges}
    nxt: dict[int, int] = {}
    for a, b in have:
        if (b, a) not in have:
            if b in nxt:
                return None
            nxt[b] = a
    loops = []
    while nxt:
        start = next(iter(nxt))
        loop, v = [start], nxt.pop(start)
        while v != start:
            if v not in nxt:
                return None
            loop.append(v)
            v = nxt.pop(v)
        loops.append(loop)
    return loops


def _drop_around_bad_vertices(mesh: o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    """Remove the triangles touching non-manifold vertices or edges (a hole is then a simple loop)."""
    mesh.remove_non_manifold_edges()
    bad = np.asarray(mesh.get_non_manifold_vertices())
    t = np.asarray(mesh.triangles)
    tri = np.asarray(triangles_boundary_vertices(t))
    bad = np.union1d(bad, tri)
    if len(bad):
        mesh.remove_triangles_by_mask(np.isin(t, bad).any(axis=1))
        mesh.remove_unreferenced_vertices()
    return clean(mesh)


def triangles_boundary_vertices(triangles: np.ndarray) -> np.ndarray:
    """Vertices with more than one outgoing boundary edge (where two holes touch)."""
    tri = np.asarray(triangles, dtype=np.int64)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    have = {(int(a), int(b)) for a, b in edges}
    starts = [b for a, b in have if (b, a) not in have]
    values, counts = np.unique(np.asarray(starts, dtype=np.int64), return_counts=True)
    return values[counts > 1]


def close_holes(mesh: o3d.geometry.TriangleMesh, attempts: int = 4) -> o3d.geometry.TriangleMesh:
    """Close every hole with a fan around its centroid.

    The holes are the few places where cleaning removed triangles because two sheets of the surface
    touched (a carton's sealed fin): first the triangles around non-manifold vertices go too, so every hole
    is a simple loop, then each loop is fanned. Returns the mesh as it is when a loop stays ambiguous after
    ``attempts`` (the caller's watertightness check then says so).
    """
    for _ in range(attempts):
        loops = boundary_loops(np.asarray(mesh.triangles))
        if loops is not None:
            break
        mesh = _drop_around_bad_vertices(mesh)
    if not loops:
        return mesh
    v = np.asarray(mesh.vertices)
    t = np.asarray(mesh.triangles)
    new_v, new_t = [v], [t]
    colours = [np.asarray(mesh.vertex_colors)] if mesh.has_vertex_colors() else None
    n = len(v)
    for loop in loops:
        ring = np.asarray(loop)
        new_v.append(v[ring].mean(axis=0, keepdims=True))
        if colours is not None:
            colours.append(colours[0][ring].mean(axis=0, keepdims=True))
        new_t.append(np.column_stack([ring, np.roll(ring, -1), np.full(len(ring), n)]))
        n += 1
    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.vstack(new_v)),
                                    o3d.utility.Vector3iVector(np.vstack(new_t).astype(np.int32)))
    if colours is not None:
        out.vertex_colors = o3d.utility.Vector3dVector(np.vstack(colours))
    return out


def tsdf_points(frames: list[PosedFrame], T_model_object: np.ndarray, bounds_object: tuple[np.ndarray, np.ndarray],
                config: SurfaceConfig = SurfaceConfig()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The TSDF-fused surface of ``frames`` inside ``bounds_object`` (object frame): xyz, outward normals
    (the signed distance's gradient), rgb (uint8).

    A uniform volume: a cube over the bounds at ``tsdf_voxel_m`` (Open3D's scalable, hashed volume integrates
    nothing in the 0.20 build used here: its extraction returns no points even for a flat wall in front of
    the camera).
    """
    if not frames:
        raise ExportError("the session has no registered frames to fuse", code="no_frames")
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds_object)
    length = float((hi - lo).max())
    volume = o3d.pipelines.integration.UniformTSDFVolume(
        length=length, resolution=int(np.ceil(length / config.tsdf_voxel_m)), sdf_trunc=config.tsdf_trunc_m,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.RGB8, origin=lo.reshape(3, 1))
    T_object_model = invert(T_model_object)
    for pf in frames:
        f = pf.frame
        intr = o3d.camera.PinholeCameraIntrinsic(f.intrinsics.width, f.intrinsics.height, f.intrinsics.fx,
                                                 f.intrinsics.fy, f.intrinsics.cx, f.intrinsics.cy)
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(f.color)), o3d.geometry.Image(np.ascontiguousarray(f.depth)),
            depth_scale=1.0 / f.depth_scale, depth_trunc=config.tsdf_depth_max_m, convert_rgb_to_intensity=False)
        volume.integrate(rgbd, intr, np.ascontiguousarray(invert(T_object_model @ pf.T_model_camera)))
    pcd = volume.extract_point_cloud()
    xyz = np.asarray(pcd.points)
    inside = np.all((xyz >= lo) & (xyz <= hi), axis=1) & (xyz[:, 2] > TABLE_CUT_M)
    pts = xyz[inside]
    if len(pts) < 100:
        raise ExportError("the fused volume holds almost nothing inside the model's bounds", code="no_surface",
                          detail={"points": int(len(pts))})
    if pcd.has_normals():
        normals = np.asarray(pcd.normals)[inside]
    else:
        p = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        p.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.005, max_nn=30))
        normals = orient_outward(pts, np.asarray(p.normals))
    rgb = np.clip(np.asarray(pcd.colors)[inside] * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return pts, normals, rgb


def to_object(T_model_object: np.ndarray, xyz: np.ndarray, normals: np.ndarray | None
              ) -> tuple[np.ndarray, np.ndarray | None]:
    """Model-frame points (and normals) in the object frame."""
    T = invert(T_model_object)
    return transform_points(T, xyz), None if normals is None else rotate_vectors(T, normals)

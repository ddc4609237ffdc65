"""Figures of an export against the simulator's ground truth (evaluation only, simulated sessions).

The mesh and the point model are measured by the one evaluator (``services/registration/evaluation``) the
acquisition reports its accuracy with, as the acquisition calls it: 60,000 true surface samples posed where
the object stood in view 0 (``T_base_object_true`` of the first scan), ICP-aligned from there, Chamfer
distance in millimetres. The
mesh is sampled uniformly by area into as many points as the point model has, so both are compared at the
same density.

The volume ratio is split into what the flat cap adds and the rest (``volume_split``): the true object's
underside above its lowest point, inside its outline (a can's recessed bottom), is never seen and the cap
closes it flat, so that volume is measured on the true mesh (rays up from the table); the rest is the mesh's
own error, with the side wall's signed distance to the true surface (is the wall biased outward?).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import open3d as o3d

from common.errors import ObjscanError
from services.export.inputs import SessionModel
from services.registration.api import evaluate_model, sample_mesh

#: True surface samples, as many as the acquisition's own evaluation draws.
GT_POINTS = 60000


#: Points sampled on the mesh to measure its side wall's signed distance to the true surface.
SIDE_SAMPLES = 20000
#: Grid step (m) of the rays cast up at the true object's underside.
UNDERSIDE_STEP_M = 0.0005


def true_surface(model: SessionModel, n: int = GT_POINTS) -> tuple[np.ndarray, float, o3d.geometry.TriangleMesh] | None:
    """True surface samples and mesh posed in ``base`` at view 0 and the true volume (m^3), or None outside the
    simulator.

    Points, as the acquisition's own evaluation uses (``gt_points`` of the twin, 60,000 of them).
    """
    import trimesh

    from services.sim.catalogue import load_object
    from services.sim.ground_truth import posed_surface

    T = model.ground_truth_pose()
    name = model.data.get("object")
    if T is None or not name:
        return None
    try:
        obj = load_object(str(name))
    except ObjscanError:
        return None
    pts = posed_surface(obj, T, n)
    volume = abs(float(trimesh.Trimesh(obj.vertices, obj.triangles, process=False).volume))
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(obj.vertices @ T[:3, :3].T + T[:3, 3])),
                                     o3d.utility.Vector3iVector(np.array(obj.triangles, dtype=np.int32)))
    return pts, volume, mesh


def volume_split(mesh_object: o3d.geometry.TriangleMesh, true_object: o3d.geometry.TriangleMesh,
                 mesh_volume: float, true_volume: float) -> dict[str, Any]:
    """What the flat cap adds to the volume (the true underside's recess) and the rest, both meshes aligned in
    the object frame (z up, the table at the true object's lowest point).

    ``recess_m3``: the volume between the true underside and the plane of its lowest point, inside its
    outline (rays cast up on a 0.5 mm grid; a ray that first meets the true mesh more than the footprint band
    above that plane went through a gap in the true mesh or past the outline and adds nothing).
    ``recess_median_depth_mm``: the median depth of the cells deeper than 1 mm.
    ``volume_ratio_recess_filled``: mesh volume over (true volume + recess), the ratio the mesh would have
    if the recess were solid. ``side_signed_mm``: median signed distance (outward positive) to the true
    surface of points sampled uniformly on the mesh between the footprint band and the top band.
    """
    from services.export.cap import FOOTPRINT_BAND_M

    tv = np.asarray(true_object.vertices)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(true_object))
    lo, hi = tv.min(axis=0), tv.max(axis=0)
    xs = np.arange(lo[0], hi[0], UNDERSIDE_STEP_M)
    ys = np.arange(lo[1], hi[1], UNDERSIDE_STEP_M)
    gx, gy = np.meshgrid(xs, ys)
    rays = np.zeros((gx.size, 6), dtype=np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2], rays[:, 5] = gx.ravel(), gy.ravel(), lo[2] - 0.01, 1.0
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    depth = t_hit[np.isfinite(t_hit)] - 0.01
    depth = depth[depth <= FOOTPRINT_BAND_M]
    recess = float(np.clip(depth, 0.0, None).sum()) * UNDERSIDE_STEP_M ** 2
    v = sample_mesh(mesh_object, SIDE_SAMPLES)
    side = v[(v[:, 2] > lo[2] + FOOTPRINT_BAND_M) & (v[:, 2] < hi[2] - FOOTPRINT_BAND_M)]
    side_mm = None
    if len(side):
        near = scene.compute_closest_points(o3d.core.Tensor(side.astype(np.float32)))
        c, n = near["points"].numpy(), near["primitive_normals"].numpy()
        side_mm = round(1000.0 * float(np.median(np.einsum("ij,ij->i", side - c, n))), 3)
    deep = depth[depth > 0.001]
    median_depth = round(1000.0 * float(np.median(deep)), 2) if deep.size else 0.0
    return {"recess_m3": recess, "recess_median_depth_mm": median_depth,
            "volume_ratio_recess_filled": mesh_volume / (true_volume + recess) if true_volume > 0 else None,
            "side_signed_mm": side_mm}


def ground_truth_figures(model: SessionModel, mesh_object: o3d.geometry.TriangleMesh, T_model_object: np.ndarray,
                         mesh_volume: float, seed: int = 0) -> dict[str, Any] | None:
    """``mesh_chamfer_mm``, ``points_chamfer_mm``, ``volume_ratio`` (+ details), or None without ground truth."""
    truth = true_surface(model)
    if truth is None:
        return None
    gt, gt_volume, true_mesh = truth
    posed = o3d.geometry.TriangleMesh(mesh_object)
    posed.transform(T_model_object)
    samples = sample_mesh(posed, len(model.xyz), seed=seed)
    points = evaluate_model(model.xyz, gt, align=True, init_T=np.eye(4), seed=seed)
    meshed = evaluate_model(samples, gt, align=True, init_T=np.eye(4), seed=seed)
    # the true mesh moved where the aligned mesh is, in the object frame
    T_object_true = np.linalg.inv(T_model_object) @ np.linalg.inv(np.asarray(meshed["T_gt_model"]))
    true_object = o3d.geometry.TriangleMesh(true_mesh).transform(T_object_true)
    keys = ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")
    return {"mesh_chamfer_mm": meshed["chamfer_mm"], "points_chamfer_mm": points["chamfer_mm"],
            "volume_ratio": mesh_volume / gt_volume if gt_volume > 0 else None,
            "true_volume_m3": gt_volume,
            "volume_split": volume_split(mesh_object, true_object, mesh_volume, gt_volume),
            "mesh": {k: meshed[k] for k in keys}, "points": {k: points[k] for k in keys}}

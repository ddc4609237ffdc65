"""Convex collision parts that stay close to the surface.

Simulators collide meshes through convex hulls. The twin's decomposition (``services/sim/collision_shapes``)
favours few parts for grasp contacts; an exported asset must also rest and roll like the object, so here the
parts are checked against the surface: the hull alone when it stays within ``tolerance_m`` of the mesh
(boxes, cans), else CoACD (the closer of hull and CoACD parts is kept, and its deviation reported: the
~2 mm aim is not always met, e.g. at a carton's sealed fin).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull

from services.sim.collision_shapes import COACD_PARAMS, convex_parts, have_coacd

#: Parts may stand out of the surface by this much (m): about the model's own accuracy.
TOLERANCE_M = 0.002
#: CoACD concavity thresholds tried in turn (its own unit: a fraction of the mesh's size). One run: each
#: took minutes of CPU on a scanned carton with up to 32 parts, and tighter thresholds did not bring the
#: parts within 2 mm of a sealed fin (measured on the milk session; docs/export.md).
COACD_THRESHOLDS = (0.05,)
#: Most parts CoACD may make (MuJoCo collides every pair: few parts keep the contacts cheap).
MAX_PARTS = 12


@dataclass
class CollisionParts:
    """Convex parts (hull vertices, object frame), how they were made and how far they stand out."""

    parts: list[np.ndarray]
    method: str
    max_deviation_m: float

    def hull_triangles(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Vertices and outward-wound triangles of part ``k``'s hull (for STL/OBJ files)."""
        pts = self.parts[k]
        hull = ConvexHull(pts)
        tris = hull.simplices.copy()
        centre = pts.mean(axis=0)
        for i, (a, b, c) in enumerate(tris):
            n = np.cross(pts[b] - pts[a], pts[c] - pts[a])
            if n @ (pts[a] - centre) < 0:
                tris[i] = (a, c, b)
        return pts, tris


def deviation(parts: list[np.ndarray], mesh: o3d.geometry.TriangleMesh, samples_per_part: int = 4000) -> float:
    """Largest distance (m) from the parts' hull surfaces outside the mesh to the mesh's surface.

    Faces of a part inside the mesh (where two parts meet) are not surface and are not counted.
    """
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    worst = 0.0
    for pts in parts:
        hull = ConvexHull(pts)
        part = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(pts),
                                         o3d.utility.Vector3iVector(hull.simplices.astype(np.int32)))
        sample = np.asarray(part.sample_points_uniformly(samples_per_part).points, dtype=np.float32)
        d = scene.compute_signed_distance(o3d.core.Tensor(sample)).numpy()
        outside = d[d > 0]
        if outside.size:
            worst = max(worst, float(np.percentile(outside, 99.5)))
    return worst


def collision_parts(mesh: o3d.geometry.TriangleMesh, tolerance_m: float = TOLERANCE_M) -> CollisionParts:
    """Parts within ``tolerance_m`` of ``mesh`` (closed, object frame): the hull, else tightening CoACD runs."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int32)
    parts, _ = convex_parts(v, t, method="hull")
    dev = deviation(parts, mesh)
    if dev <= tolerance_m or not have_coacd():
        return CollisionParts(parts, "hull", dev)
    best = CollisionParts(parts, "hull", dev)
    for threshold in COACD_THRESHOLDS:
        params = {**COACD_PARAMS, "threshold": threshold, "max_convex_hull": MAX_PARTS}
        parts, method = convex_parts(v, t, method="coacd", params=params)
        dev = deviation(parts, mesh)
        if dev < best.max_deviation_m:
            best = CollisionParts(parts, method, dev)
        if dev <= tolerance_m:
            break
    return best

"""Convex collision parts that stay close to the surface, in a bounded CPU time.

Simulators collide meshes through convex hulls. The twin's decomposition (``services/sim/collision_shapes``)
favours few parts for grasp contacts; an exported asset must also rest and roll like the object, so here the
parts are checked against the surface, cheapest first: the hull alone when it stays within ``tolerance_m`` of
the mesh (boxes); else horizontal slabs, cut into halves, quarters or sectors where a slab is concave
(``slabs.py``: a can's rim around its recessed lid, within ~1.8 mm in 1-2 s of CPU, the same parts for the
same mesh); else, where straight cuts cannot follow the surface (a carton's folded top), CoACD, and the
closest of all the sets is kept, with how far it stands out.

What drove CoACD's parts out of the surface was the part count, not the search: asked for at most 12 parts,
CoACD decomposes to its concavity threshold and then merges parts pairwise down to 12, and the merged parts
spanned a carton's gable and a can's recessed lid (3-10 mm out), and the merging took most of the CPU (22 s
on the milk carton). Without the cap and with half the tree search, threshold 0.05 kept the cans' parts
within about 2 mm in 4-5 s. CoACD's threshold is relative to the object's size (its parts stood out about
0.3 x threshold x the bounding box's diagonal on the HOPE cans, 0.4 on the cartons: 2 mm on a can, 4.4-4.8
mm on a 19 cm carton), so the loose run and one at the threshold the size calls for (at least 0.025; 0.030
on the cartons: 2.8-3.0 mm) run side by side, each in a child process under its share of a CPU budget (its
search cannot be interrupted otherwise, and its CPU time varies several-fold between nearly identical
meshes): a run out of time leaves the other's parts, the slabs' or the hull (``parts_coacd`` says which runs
ran and how they ended: docs/export.md).
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial import ConvexHull

from services.export.slabs import hull_samples, slab_parts
from services.sim.collision_shapes import COACD_PARAMS, have_coacd, hull_vertices

#: Parts may stand out of the surface by this much (m): about the model's own accuracy.
TOLERANCE_M = 0.002
#: The range of CoACD's concavity threshold (its own unit, relative to the object's size): the loosest
#: runs first (4-5 s on every HOPE mesh), the tightest bounds the part count and the CPU of the second run
#: (113 parts, 11-20+ s on the milk carton).
COACD_THRESHOLDS = (0.025, 0.05)
#: How far CoACD's parts stood out, per unit of threshold and of bounding-box diagonal (measured on the
#: HOPE meshes: 0.28-0.31 on the cans, about 0.4 on the cartons, which end nearer 3 mm than 2).
DEVIATION_PER_THRESHOLD = 0.3
#: No cap on the part count (-1): merging down to a cap was what made parts stand out (module doc).
MAX_PARTS = -1
#: CoACD's runs, side by side: (loose threshold, else the one the object's size calls for; triangles of the
#: decimated copy it decomposes, parts checked against the full mesh; share of the CPU budget). Its result
#: on a carton swings with the copy: threshold 0.030 left the orange-juice carton's parts 6.3 mm out on the
#: 3,000-triangle copy (20 parts, 4.4 s) and 2.9 mm on the 6,000 one (28 parts, 6.2 s), while on the milk
#: carton the 3,000 copy gave 2.8 mm (85 parts) and the 6,000 copy ran past 14 s. Two copies at the tight
#: threshold, and the loose run as a cheap floor (4.4-7.5 mm on the cartons, 3-5 s), keep the closest.
COACD_RUNS = ((True, 3000, 2.0), (False, 3000, 4.0), (False, 6000, 5.0))
#: A coarser search than the twin's: 15 tree-search iterations instead of 60.
COACD_EFFORT = {"preprocess_resolution": 20, "mcts_iterations": 15, "resolution": 500}
#: CPU seconds CoACD's runs may take together (shared as ``COACD_RUNS`` says: 5.1, 10.2 and 12.7 s). CoACD's
#: CPU time is erratic: at threshold 0.05 it took 4.6 s on one Poisson mesh of the milk carton and 16.3 s on
#: another run's (the same surface to within numerical noise). The rest of an export is about 10 s of CPU on
#: one core, and the runs use the other meanwhile.
COACD_CPU_BUDGET_S = 28.0
#: Samples per part on its hull surface when measuring how far it stands out.
SAMPLES_PER_PART = 4000
_WORKER = Path(__file__).with_name("coacd_worker.py")


@dataclass
class CollisionParts:
    """Convex parts (hull vertices, object frame), how they were made (``method``: ``hull``, ``slabs`` or
    ``coacd``) and how far they stand out.

    ``max_deviation_m``: the worst part's 99.5th percentile distance outside the mesh; ``p95_deviation_m``:
    the 95th percentile over the parts' whole surface outside the mesh (weighted by area). ``coacd``: what
    the decomposition did (``collision_parts``).
    """

    parts: list[np.ndarray]
    method: str
    max_deviation_m: float
    p95_deviation_m: float = 0.0
    coacd: str = "not_needed"

    def hull_triangles(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Vertices and outward-wound triangles of part ``k``'s hull (for STL/OBJ files)."""
        pts = self.parts[k]
        hull = ConvexHull(pts)
        tris = hull.simplices.copy()
        a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
        inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - pts.mean(axis=0)) < 0
        tris[inward] = tris[inward][:, [0, 2, 1]]
        return pts, tris


def surface_scene(mesh: o3d.geometry.TriangleMesh) -> o3d.t.geometry.RaycastingScene:
    """A ray-casting scene of ``mesh`` (signed distances to it), built once per mesh."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return scene


def deviation_figures(parts: list[np.ndarray], mesh: o3d.geometry.TriangleMesh,
                      samples_per_part: int = SAMPLES_PER_PART,
                      scene: o3d.t.geometry.RaycastingScene | None = None) -> tuple[float, float]:
    """How far (m) the parts' hull surfaces outside the mesh stand from the mesh's surface: (max, p95).

    Max: the largest over parts of each part's 99.5th percentile (a maximum robust to sampling). P95: the
    95th percentile over all parts' outside samples, each weighted by its part's area per sample. Faces of
    a part inside the mesh (where two parts meet) are not surface and are not counted.
    """
    scene = surface_scene(mesh) if scene is None else scene
    worst = 0.0
    values, weights = [], []
    for pts in parts:
        sample = hull_samples(pts, samples_per_part)
        if sample is None:
            continue
        d = scene.compute_signed_distance(o3d.core.Tensor(sample.astype(np.float32))).numpy()
        outside = d[d > 0]
        if outside.size:
            worst = max(worst, float(np.percentile(outside, 99.5)))
            values.append(outside)
            weights.append(np.full(outside.size, ConvexHull(pts).area / samples_per_part))
    if not values:
        return worst, 0.0
    v, w = np.concatenate(values), np.concatenate(weights)
    order = np.argsort(v)
    cum = np.cumsum(w[order])
    return worst, float(v[order][np.searchsorted(cum, 0.95 * cum[-1])])


def deviation(parts: list[np.ndarray], mesh: o3d.geometry.TriangleMesh,
              samples_per_part: int = SAMPLES_PER_PART) -> float:
    """The largest distance (m) the parts stand out of ``mesh`` (``deviation_figures``' max)."""
    return deviation_figures(parts, mesh, samples_per_part)[0]


def coacd_in_budget(vertices: np.ndarray, triangles: np.ndarray, params: dict,
                    cpu_budget_s: float) -> tuple[list[np.ndarray] | None, str]:
    """CoACD's parts (hull vertices) from a child process limited to ``cpu_budget_s`` of CPU, and how it went.

    ``(parts, "ok")``, or ``(None, "over_budget")`` when the limit (or a generous wall-clock bound for a
    machine so loaded the child hardly runs) ended it, or ``(None, "failed")``.
    """
    buf = io.BytesIO()
    np.savez(buf, vertices=np.asarray(vertices, dtype=np.float64), triangles=np.asarray(triangles, dtype=np.int32),
             params=json.dumps(params), cpu_budget_s=float(cpu_budget_s))
    try:
        done = subprocess.run([sys.executable, str(_WORKER)], input=buf.getvalue(), capture_output=True,
                              timeout=max(120.0, 40.0 * cpu_budget_s), check=False)
    except subprocess.TimeoutExpired:
        return None, "over_budget"
    if done.returncode != 0:
        over = done.returncode in (-9, -24)  # SIGKILL (hard limit), SIGXCPU (soft limit)
        return None, "over_budget" if over else "failed"
    try:
        with np.load(io.BytesIO(done.stdout)) as z:
            raw = [z[k] for k in sorted(z.files, key=lambda s: int(s[1:]))]
    except (OSError, ValueError, KeyError):
        return None, "failed"
    parts = [hull_vertices(p) for p in raw if len(p) >= 4 and np.ptp(p, axis=0).min() > 1e-5]
    return (parts, "ok") if parts else (None, "failed")


def coacd_threshold(vertices: np.ndarray, tolerance_m: float) -> float:
    """CoACD's threshold for parts within about ``tolerance_m`` of an object this size, within the range."""
    diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    lo, hi = COACD_THRESHOLDS
    return float(np.clip(tolerance_m / (DEVIATION_PER_THRESHOLD * max(diagonal, 1e-6)), lo, hi))


def collision_parts(mesh: o3d.geometry.TriangleMesh, tolerance_m: float = TOLERANCE_M,
                    cpu_budget_s: float = COACD_CPU_BUDGET_S) -> CollisionParts:
    """Parts of ``mesh`` (closed, object frame): the hull within ``tolerance_m``, else the slabs within it,
    else the closest of the hull, the slabs and CoACD's runs side by side (``COACD_RUNS``: the loose threshold
    and the one the object's size calls for, on two copies), sharing ``cpu_budget_s`` of CPU.

    ``coacd`` of the result: ``not_needed`` (the hull or the slabs were close enough), ``unavailable``, or
    one ``THRESHOLD@TRIANGLES:STATUS`` per run (``"0.050@3000:ok"``, ``"0.030@6000:over_budget"``...) joined
    by commas.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int32)
    hull = [hull_vertices(v)]
    scene = surface_scene(mesh)
    best = CollisionParts(hull, "hull", *deviation_figures(hull, mesh, scene=scene))
    if best.max_deviation_m <= tolerance_m:
        return best
    slabs = slab_parts(mesh, tolerance_m)
    if slabs is not None:
        found = CollisionParts(slabs, "slabs", *deviation_figures(slabs, mesh, scene=scene))
        if found.max_deviation_m < best.max_deviation_m:
            best = found
        if best.max_deviation_m <= tolerance_m:
            return best
    if not have_coacd():
        best.coacd = "unavailable"
        return best
    size_threshold = coacd_threshold(v, tolerance_m)
    plan: dict[tuple[float, int], float] = {}  # (threshold, triangles of the copy) -> share of the budget
    for loose, n, share in COACD_RUNS:
        plan.setdefault((COACD_THRESHOLDS[1] if loose else size_threshold, min(n, len(t))), share)
    keys = list(plan)
    copies = {n: mesh.simplify_quadric_decimation(n) if n < len(t) else mesh for _, n in keys}

    def run(k: int) -> tuple[list[np.ndarray] | None, str]:
        threshold, n = keys[k]
        params = {**COACD_PARAMS, **COACD_EFFORT, "threshold": threshold, "max_convex_hull": MAX_PARTS}
        budget = cpu_budget_s * plan[keys[k]] / sum(plan.values())
        return coacd_in_budget(np.asarray(copies[n].vertices), np.asarray(copies[n].triangles), params, budget)

    # the runs at once: each is a single-threaded child, and the export's other steps run meanwhile
    with ThreadPoolExecutor(len(keys)) as pool:
        done = list(pool.map(run, range(len(keys))))
    runs = []
    for (threshold, n), (parts, status) in zip(keys, done, strict=True):
        runs.append(f"{threshold:.3f}@{n}:{status}")
        if parts is not None:
            found = CollisionParts(parts, "coacd", *deviation_figures(parts, mesh, scene=scene))
            if found.max_deviation_m < best.max_deviation_m:
                best = found
    best.coacd = ",".join(runs)
    return best


"""Benchmark: 4PCS (ours) vs FPFH-RANSAC vs FGR (Open3D) for the dynamic stage's global alignment.

Cases (all with exact ground truth):
- ``hope``: neighbouring simulated views (~30 degrees apart, hand-turned profile) of the HOPE objects in
  shared/data, from ``bench.synthetic``. Two scenarios per pair:
  ``random`` - the source is first moved by a random rigid transform (what "global" must handle) and
  ``prerotated`` - the source is pre-rotated by its commanded turn about its estimated centre, as the
  paper's pre-processing does (what the pipeline actually feeds the global stage).
- ``hippo``: the Super4PCS repository's scan, two hidden-point-removal views 30 degrees apart (scaled to
  20 cm), source randomly moved.

Per case and method: global registration at 8 mm (4PCS with the paper's overlaps 0.9/0.85/0.8), then a
local refinement (colored ICP at 4 mm then 2 mm for the colored HOPE views, as the pipeline's local stage
is color-driven; point-to-plane ICP for the hippo). Success = rotation error < 5 degrees after refinement.
In the ``prerotated`` scenario every method gets the pre-rotation as ``prior_T`` (kept when it fits as
well - what the pipeline would do). A ``none`` row (refinement from the prior / identity, no global
stage) is the baseline measured in the same run. Rotationally symmetric cans cannot be resolved by
geometry alone; the per-object figures show it.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter

import numpy as np
from scipy.spatial.transform import Rotation

from common.geometry import invert, make_transform, rotation_about_line, transform_error, transform_points
from services.registration.api import global_register, refine_icp, to_o3d

METHODS = ("4pcs", "fpfh_ransac", "fgr")
SUCCESS_DEG = 5.0
DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


@dataclass
class Case:
    name: str
    group: str  # object name or "hippo"
    scenario: str  # "random" | "prerotated"
    source: np.ndarray
    target: np.ndarray
    T_true: np.ndarray  # target ~ T_true @ source
    source_rgb: np.ndarray | None = None
    target_rgb: np.ndarray | None = None
    prior_T: np.ndarray | None = None  # what the pipeline already believes (pre-rotated views: identity)


def _random_motion(rng: np.random.Generator, centre: np.ndarray) -> np.ndarray:
    """A random rotation about ``centre`` plus up to 10 cm of translation."""
    R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
    return make_transform(R, centre - R @ centre + rng.uniform(-0.1, 0.1, 3))


def hope_cases(objects: list[str], pairs: list[int], seed: int = 0) -> list[Case]:
    from bench.synthetic import synthetic_views
    from services.sim.catalogue import hope_names

    available = set(hope_names())
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    for obj in objects:
        if obj not in available:
            continue
        views = synthetic_views(obj, views=12, scans_per_view=3, profile="hand-turned", seed=seed).views
        for k in pairs:
            tgt, src = views[k], views[k + 1]
            T_k_k1 = invert(tgt.T_view0_view_true) @ src.T_view0_view_true
            src_xyz = src.xyz.astype(np.float64)
            T_pre = rotation_about_line(np.array([0.0, 0.0, 1.0]), src.center,
                                        math.radians(-(src.commanded_turn_deg - tgt.commanded_turn_deg)))
            T_rand = _random_motion(rng, src_xyz.mean(axis=0))
            for scenario, T_move in (("random", T_rand), ("prerotated", T_pre)):
                cases.append(Case(f"{obj}:{k}-{k + 1}:{scenario}", obj, scenario, transform_points(T_move, src_xyz),
                                  tgt.xyz.astype(np.float64), T_k_k1 @ invert(T_move),
                                  source_rgb=src.rgb, target_rgb=tgt.rgb,
                                  prior_T=np.eye(4) if scenario == "prerotated" else None))
    return cases


def hippo_cases(azimuths: list[float], seed: int = 0) -> list[Case]:
    import open3d as o3d

    path = DATA / "clouds" / "super4pcs_hippo" / "hippo1.ply"
    if not path.is_file():
        return []
    full = np.asarray(o3d.io.read_point_cloud(str(path)).points) * 0.2
    rng = np.random.default_rng(seed)

    def view(az_deg: float) -> np.ndarray:
        c = full.mean(axis=0)
        az, el = math.radians(az_deg), math.radians(20.0)
        cam = c + 0.6 * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(full))
        return full[np.asarray(pcd.hidden_point_removal(cam, 60.0)[1])]

    cases = []
    for az in azimuths:
        tgt, src = view(az), view(az + 30.0)
        T_rand = _random_motion(rng, src.mean(axis=0))
        cases.append(Case(f"hippo:{az:g}-{az + 30:g}:random", "hippo", "random", transform_points(T_rand, src),
                          tgt, invert(T_rand)))
    return cases


def _local_refinement(case: Case, T: np.ndarray) -> tuple[np.ndarray, float]:
    """Colored ICP at 4 then 2 mm when the views have colors (as the pipeline's local stage), else
    point-to-plane ICP. Geometry alone lets a can slide about its axis; its print pins it."""
    if case.source_rgb is None or case.target_rgb is None:
        T_mid, _, _ = refine_icp(case.source, case.target, T, voxel=0.004)
        T_fine, fitness, _ = refine_icp(case.source, case.target, T_mid, voxel=0.002)
        return T_fine, fitness
    import open3d as o3d

    reg = o3d.pipelines.registration

    def cloud(xyz: np.ndarray, rgb: np.ndarray, voxel: float) -> o3d.geometry.PointCloud:
        pcd = to_o3d(xyz, rgb).voxel_down_sample(voxel)
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
        return pcd

    fitness = 0.0
    for voxel in (0.004, 0.002):
        s, t = cloud(case.source, case.source_rgb, voxel), cloud(case.target, case.target_rgb, voxel)
        try:
            out = reg.registration_colored_icp(s, t, 2 * voxel, T, reg.TransformationEstimationForColoredICP(),
                                               reg.ICPConvergenceCriteria(max_iteration=50))
        except RuntimeError:  # no correspondences at all: the global estimate was far off
            return T, 0.0
        T, fitness = np.array(out.transformation), float(out.fitness)
    return T, fitness


def _rms_error(T_est: np.ndarray, T_true: np.ndarray, pts: np.ndarray) -> float:
    d = transform_points(T_est, pts) - transform_points(T_true, pts)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def evaluate_case(case: Case, method: str, seed: int = 0) -> dict:
    t0 = perf_counter()
    if method == "none":
        T_global, seconds_global = (np.eye(4) if case.prior_T is None else case.prior_T), 0.0
    else:
        res = global_register(case.source, case.target, method, voxel=0.008, seed=seed, prior_T=case.prior_T)
        T_global, seconds_global = res.T, res.seconds
    T_fine, fitness = _local_refinement(case, T_global)
    rot_raw = transform_error(T_global, case.T_true)[1]
    rot = transform_error(T_fine, case.T_true)[1]
    return {
        "case": case.name, "group": case.group, "scenario": case.scenario, "method": method,
        "seconds_global": seconds_global, "seconds_total": perf_counter() - t0,
        "rotation_error_raw_deg": rot_raw, "rotation_error_deg": rot,
        "point_rms_error_mm": 1000 * _rms_error(T_fine, case.T_true, case.source),
        "fitness": fitness, "success": bool(rot < SUCCESS_DEG),
    }


def _summary(rows: list[dict]) -> dict:
    if not rows:
        return {"n_cases": 0}
    return {
        "n_cases": len(rows),
        "success_rate": float(np.mean([r["success"] for r in rows])),
        "raw_success_rate": float(np.mean([r["rotation_error_raw_deg"] < SUCCESS_DEG for r in rows])),
        "time_median_s": float(np.median([r["seconds_global"] for r in rows])),
        "time_max_s": float(np.max([r["seconds_global"] for r in rows])),
        "rotation_error_raw_median_deg": float(np.median([r["rotation_error_raw_deg"] for r in rows])),
    }


def run(quick: bool = False) -> dict:
    """Measure every method on every case; returns per-method and per-scenario figures plus raw rows."""
    t0 = perf_counter()
    if quick:
        cases = hope_cases(["milk", "cream_cheese"], [0, 5]) + hippo_cases([0.0])
    else:
        cases = hope_cases(["milk", "cream_cheese", "orange_juice", "tomato_sauce", "alphabet_soup"],
                           [0, 3, 6, 9]) + hippo_cases([0.0, 90.0, 180.0, 270.0])
    rows = [evaluate_case(c, m) for c in cases for m in (*METHODS, "none")]
    out: dict = {"success_threshold_deg": SUCCESS_DEG, "quick": quick, "n_cases": len(cases), "methods": {}}
    for m in (*METHODS, "none"):
        mine = [r for r in rows if r["method"] == m]
        entry = _summary(mine)
        entry["per_scenario"] = {s: _summary([r for r in mine if r["scenario"] == s])
                                 for s in ("random", "prerotated")}
        entry["per_group"] = {g: _summary([r for r in mine if r["group"] == g])
                              for g in sorted({r["group"] for r in mine})}
        out["methods"][m] = entry
    base = out["methods"]["fpfh_ransac"]
    for m in ("4pcs", "fgr"):
        out[f"time_ratio_{m}_vs_fpfh_ransac"] = out["methods"][m].get("time_median_s", 0) / max(
            base.get("time_median_s", 0), 1e-9)
        out[f"success_delta_{m}_vs_fpfh_ransac"] = out["methods"][m].get("success_rate", 0) - base.get(
            "success_rate", 0)
    out["rows"] = rows
    out["seconds_total"] = perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    result = run(quick="--quick" in argv)
    if "--json" in argv:
        print(json.dumps(result, indent=2))
        return
    print(f"global registration benchmark ({result['n_cases']} cases, success = rotation error < "
          f"{SUCCESS_DEG:g} deg after ICP refinement)")
    print(f"{'method':<12} {'scenario':<11} {'n':>3} {'success':>8} {'t_median_s':>11} {'t_max_s':>8} "
          f"{'raw_err_deg':>12}")
    for m, entry in result["methods"].items():
        for scen, s in [("all", entry), *entry["per_scenario"].items()]:
            if s.get("n_cases"):
                print(f"{m:<12} {scen:<11} {s['n_cases']:>3} {s['success_rate']:>8.2f} {s['time_median_s']:>11.3f} "
                      f"{s['time_max_s']:>8.3f} {s['rotation_error_raw_median_deg']:>12.1f}")
    print("per object (success rate, all scenarios):")
    groups = sorted({r["group"] for r in result["rows"]})
    print(f"{'method':<12} " + " ".join(f"{g:>14}" for g in groups))
    for m, entry in result["methods"].items():
        print(f"{m:<12} " + " ".join(f"{entry['per_group'][g]['success_rate']:>14.2f}" for g in groups))
    print(f"time ratio 4pcs / fpfh_ransac: {result['time_ratio_4pcs_vs_fpfh_ransac']:.2f}; "
          f"total {result['seconds_total']:.1f} s")


if __name__ == "__main__":
    main()

"""Collision-part settings compared: how far CoACD's parts stand out of exported meshes, and their CPU time.

    python -m bench.export_parts DIR/milk.ply DIR/tomato_sauce.ply ... --json bench/latest/export_parts.json

Each mesh (an export's closed mesh, ``NAME.ply``, object frame) is decimated as the export does and
decomposed with each setting of ``SETTINGS`` in this process (``time.process_time``: CPU seconds, which a
loaded machine changes little); the parts are measured against the full mesh with the export's own
``deviation_figures`` (max: the worst part's 99.5th percentile distance outside the mesh; p95 over all
parts' outside surface). The settings: the previous export's (at most 12 parts, 30 tree-search
iterations) and the current one's thresholds with no cap.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from common.session_folder import atomic_write_json
from services.export.collision import COACD_EFFORT, COACD_RUNS, deviation_figures
from services.sim.collision_shapes import COACD_PARAMS, have_coacd

SETTINGS: dict[str, dict[str, Any]] = {
    "capped_12_mcts_30": {"threshold": 0.05, "max_convex_hull": 12, "mcts_iterations": 30},
    "uncapped_0.050": {"threshold": 0.05, "max_convex_hull": -1},
    "uncapped_0.035": {"threshold": 0.035, "max_convex_hull": -1},
    "uncapped_0.025": {"threshold": 0.025, "max_convex_hull": -1},
    "uncapped_0.050_nodes_5": {"threshold": 0.05, "max_convex_hull": -1, "mcts_nodes": 5},
    "uncapped_0.025_nodes_5": {"threshold": 0.025, "max_convex_hull": -1, "mcts_nodes": 5},
}


def run_one(mesh: o3d.geometry.TriangleMesh, setting: dict[str, Any], triangles: int) -> dict[str, Any]:
    """Decompose the copy decimated to ``triangles`` with ``setting``; parts, CPU seconds and deviation (mm)."""
    import coacd

    coarse = mesh.simplify_quadric_decimation(triangles) if len(mesh.triangles) > triangles else mesh
    params = {**COACD_PARAMS, **COACD_EFFORT, **setting}
    coacd.set_log_level("error")
    c0 = time.process_time()
    raw = coacd.run_coacd(coacd.Mesh(np.asarray(coarse.vertices), np.asarray(coarse.triangles)), **params)
    cpu = time.process_time() - c0
    parts = [np.asarray(v) for v, _ in raw if len(v) >= 4 and np.ptp(np.asarray(v), axis=0).min() > 1e-5]
    worst, p95 = deviation_figures(parts, mesh)
    return {"parts": len(parts), "cpu_seconds": round(cpu, 2), "max_mm": round(1000 * worst, 2),
            "p95_mm": round(1000 * p95, 2)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("meshes", nargs="+", type=Path, help="exported closed meshes (NAME.ply, object frame)")
    p.add_argument("--settings", default=",".join(SETTINGS), help="comma-separated names of SETTINGS")
    p.add_argument("--triangles", type=int, default=COACD_RUNS[0][1],
                   help="triangles of the decimated copy CoACD decomposes (the export's runs: collision.COACD_RUNS)")
    p.add_argument("--json", type=Path, required=True, help="the figures, as JSON")
    args = p.parse_args()
    if not have_coacd():
        raise SystemExit("coacd is not installed")
    rows: list[dict[str, Any]] = []
    doc = {"benchmark": "export_parts", "machine": {"cpus": os.cpu_count(), "platform": platform.platform()},
           "triangles": args.triangles, "effort": COACD_EFFORT, "rows": rows}
    for path in args.meshes:
        mesh = o3d.io.read_triangle_mesh(str(path))
        for name in args.settings.split(","):
            row = {"mesh": path.stem, "setting": name, **SETTINGS[name], "load_before": round(os.getloadavg()[0], 1),
                   **run_one(mesh, SETTINGS[name], args.triangles)}
            rows.append(row)
            print(row, flush=True)
            atomic_write_json(args.json, doc)


if __name__ == "__main__":
    main()

"""Export benchmark: every given session exported with both surface methods, figures per object.

    python -m bench.export SESSION [SESSION ...] --out DIR --json bench/latest/export.json

For each session (a finished simulated acquisition) and each surface method (``poisson``, ``tsdf``) it runs
``export_session`` and keeps the issue's figures: ``watertight``, ``mesh_chamfer_mm``, ``points_chamfer_mm``
(the point model's, same evaluator), ``volume_ratio`` (mesh volume over the true mesh's) and its split
(``volume_split``: the unseen recess the bottom cap closes, the side wall's bias), ``parts`` and how far
they stand out (``parts_deviation_mm``),
``seconds`` (the export, without the ground-truth evaluation), and the pass/fail of each target.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from typing import Any

from common.errors import ObjscanError
from common.session_folder import atomic_write_json
from services.export import METHODS, export_session

KEYS = ("watertight", "is_volume", "mesh_chamfer_mm", "points_chamfer_mm", "volume_ratio", "volume_split", "parts",
        "parts_max_deviation_mm", "parts_deviation_mm", "parts_coacd", "seconds", "cpu_seconds", "cpu_wait_seconds",
        "triangles", "textured", "timings_s", "evaluation_seconds")


def targets(r: dict[str, Any]) -> dict[str, bool]:
    """The acceptance targets of one export."""
    mesh, points = r.get("mesh_chamfer_mm"), r.get("points_chamfer_mm")
    ratio = r.get("volume_ratio")
    return {"watertight": bool(r.get("watertight")),
            "mesh_vs_points": mesh is not None and points is not None and mesh <= 1.2 * points,
            "mesh_le_1_5mm": mesh is not None and mesh <= 1.5,
            "volume_0_95_1_05": ratio is not None and 0.95 <= ratio <= 1.05,
            "seconds_le_30": r.get("seconds", 1e9) <= 30.0}


def run(sessions: list[Path], out: Path, methods: tuple[str, ...], save=None) -> dict[str, Any]:  # noqa: ANN001
    """Export every session with every method; ``save(doc)`` after each row (a long run keeps what it has)."""
    rows: list[dict[str, Any]] = []
    doc: dict[str, Any] = {"benchmark": "export", "machine": {
        "cpus": os.cpu_count(), "platform": platform.platform(),
        "note": "2-core machine shared with other engineers' runs; load average per row"}, "rows": rows}
    for method in methods:  # the default method on every session first
        for session in sessions:
            load = os.getloadavg()[0]
            try:
                r = export_session(session, out / f"{session.name}_{method}", method=method)
            except ObjscanError as exc:
                rows.append({"session": session.name, "method": method, "error": {"code": exc.code,
                                                                                   "message": exc.message}})
                if save:
                    save(doc)
                continue
            row = {"object": r["name"], "session": session.name, "method": method, "load_before": round(load, 1),
                   **{k: r.get(k) for k in KEYS}}
            row["targets"] = targets(row)
            rows.append(row)
            print(json.dumps({k: row[k] for k in ("object", "method", "mesh_chamfer_mm", "points_chamfer_mm",
                                                  "volume_ratio", "parts", "parts_deviation_mm", "seconds",
                                                  "cpu_seconds", "watertight")}),
                  flush=True)
            doc["stamp"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
            if save:
                save(doc)
    return doc


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("sessions", nargs="+", type=Path, help="finished session folders")
    p.add_argument("--out", type=Path, required=True, help="folder receiving one export per session and method")
    p.add_argument("--methods", default=",".join(METHODS), help="comma-separated surface methods")
    p.add_argument("--json", type=Path, required=True, help="the figures, as JSON")
    args = p.parse_args()
    old: list[dict[str, Any]] = []
    if args.json.exists():  # keep the rows of sessions not run this time
        try:
            old = json.loads(args.json.read_text()).get("rows", [])
        except (OSError, json.JSONDecodeError):
            old = []

    def save(doc: dict[str, Any]) -> None:
        done = {(r["session"], r["method"]) for r in doc["rows"]}
        kept = [r for r in old if (r.get("session"), r.get("method")) not in done]
        atomic_write_json(args.json, {**doc, "rows": kept + doc["rows"]})

    run(args.sessions, args.out, tuple(m for m in args.methods.split(",") if m), save=save)


if __name__ == "__main__":
    main()

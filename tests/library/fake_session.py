"""A fake-but-valid finished acquisition folder, built without any service process.

What the orchestrator would write (``services/session_store.py``), made from the same building blocks:
the twin's scans (``simulated_views`` + ``write_session``), static registration of every view
(``view_KK/view.json`` + ``object.ply``), the grasp planner on each view but the last
(``view_KK/grasps_auto.json``), dynamic registration into ``model.ply``, evaluation against the twin's
ground truth, and a ``journal.json`` / ``report.json`` with decisions and timings in the orchestrator's
format. Shared by tests/library and tests/report.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.scenario import simulated_views, write_session
from common.session_folder import atomic_write_json
from services.grasp.planner import plan_grasps_for_cloud
from services.registration.api import (
    DynamicConfig,
    build_model,
    evaluate_model,
    register_view,
    view_from_static,
    write_ply,
)
from services.sim.ground_truth import true_object_points


def build_fake_session(directory: Path, object_name: str = "milk", *, views: int = 4, turn_deg: float = 90.0,
                       seed: int = 3, profile: str = "ideal") -> Path:
    """Write a finished session of ``views`` views of ``object_name`` into ``directory``; returns it."""
    timings: dict[str, float] = {}
    decisions: list[dict] = []
    started = time.time()

    def decide(what: str, view: int, state: str, **detail) -> None:
        decisions.append({"t": round(time.time() - started, 3), "state": state, "view": view, "what": what, **detail})

    t0 = time.perf_counter()
    frames = simulated_views(object_name, views=views, turn_deg=turn_deg, seed=seed, profile=profile)
    config = {"object": object_name, "profile": profile, "seed": seed, "views": views, "turn_deg": turn_deg}
    write_session(directory, frames, extra={"config": config, "simulated": True})
    timings["scan"] = round(time.perf_counter() - t0, 3)
    results = []
    for k, view_frames in enumerate(frames):
        t0 = time.perf_counter()
        r = register_view(view_frames)
        results.append(r)
        d = directory / f"view_{k:02d}"
        write_ply(d / "object.ply", r.object_cloud)
        atomic_write_json(d / "view.json", {
            "view": k, "center": r.object_center, "height": r.object_height,
            "table": {"normal": r.table.normal, "offset": r.table.offset, "center": r.table.center},
            "scan_poses": np.stack([s.T_base_camera for s in r.scans]), "figures": r.to_json()})
        timings["register"] = round(timings.get("register", 0.0) + time.perf_counter() - t0, 3)
        decide("view registered", k, "register", points=len(r.object_cloud))
        if k == views - 1:
            break
        t0 = time.perf_counter()
        plan = plan_grasps_for_cloud(r.object_cloud, r.table)
        atomic_write_json(d / "grasps_auto.json", {
            "mode": "auto", "explanation": plan.explain(), "seconds": time.perf_counter() - t0,
            "rejections": plan.rejections.as_dict(),
            "grasps": [{"kind": g.kind, "rank": g.rank, "width": g.width, "metrics": g.metrics,
                        "contacts": g.contacts.tolist()} for g in plan.grasps]})
        timings["plan_grasp"] = round(timings.get("plan_grasp", 0.0) + time.perf_counter() - t0, 3)
        decide("grasps planned", k, "plan_grasp", mode="auto", n=len(plan.grasps))
        if plan.grasps:
            decide("turned", k, "turn", grasp=0, pose="grasp", kind=plan.grasps[0].kind)
    t0 = time.perf_counter()
    dviews = [view_from_static(r, turn_deg * k, index=k) for k, r in enumerate(results)]
    model = build_model(dviews, DynamicConfig(configuration="no_region"))
    model.write_ply(directory / "model.ply")
    timings["model"] = round(time.perf_counter() - t0, 3)
    gt = true_object_points(frames[0][0], n=30000)
    accuracy = evaluate_model(model.xyz, gt, init_T=np.eye(4))
    decide("model built", views - 1, "model", points=len(model))
    journal = {"version": 1, "config": config, "state": "done", "status": "done", "view": views - 1,
               "decisions": decisions, "timings_s": timings, "started": started, "simulated": True}
    atomic_write_json(directory / "journal.json", journal)
    atomic_write_json(directory / "report.json", {
        "model": str(directory / "model.ply"), "points": len(model), "model_figures": model.to_json(),
        "turns_commanded_deg": [turn_deg * k for k in range(views)], "accuracy": accuracy,
        "session": str(directory), "config": config, "timings_s": timings, "decisions": decisions,
        "seconds_total": round(time.time() - started, 2)})
    return directory

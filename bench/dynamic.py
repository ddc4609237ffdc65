"""Benchmark of the dynamic registration (paper Tables VI and VII) on simulated HOPE objects.

For each profile (realistic, hand-turned, robot-turned) and object: 12 views x 3 scans of the twin, the
static stage isolates each view, then the dynamic stage runs in every configuration (no_region,
no_region_crop, region, region_crop; fast pair path, paper combination), plus the pose-graph
combination, the automatic choice (the default pipeline), and an "oracle" that fuses the views with
their true poses (each view fitted alone onto the ground truth: the static stage's clouds carry the
camera's hand-eye error, so the true object motion alone is not their best fusion) - the sensor-noise
floor, measured in the same run. Chamfer distance is measured against the ground-truth mesh, without
the object's footprint (which no camera sees), after aligning the model to it as the paper does (ICP
starting from view 0's ``base``, where the model is expected).

Reported per profile and row: mean Chamfer inclusive and exclusive of the worst object, mean seconds,
and for the automatic choice the ratio to the oracle per object (target <= 1.3); on the drawn profiles the full
reconstruct time (``objscan reconstruct`` of the 12 x 3 frames written as a session folder; target <= 20 s):
in one process and with one worker process per core (at least 2), measured alongside; the figure is the
faster of the two (the CLI's default picks by core count, see ``reconstruct.default_workers``).

Where each row's turns come from (``turns`` in the JSON, per profile and per object):

- ``realistic`` and ``hand-turned``: **drawn turns**. ``simulated_views`` sets the object at each view's
  turn as the profile draws it (``services/sim/profiles.py``); no grasp, no contact. ``realistic`` (the
  benchmarks' default twin: per-scan pose error, hand-eye error, the object off the expected spot, the D435
  model calibrated on real frames, scans aimed at the estimated centre) first, then ``hand-turned``.
- ``robot-turned``: **physics acquisitions**. For each HOPE object the twin runs the whole acquisition,
  ``objscan scan --object NAME --physics mujoco --profile robot-turned --views 12 --seed 0``: the arm grasps,
  turns and sets the object down under MuJoCo contact, so the turns between views are what the contact
  simulation produced (in-hand slip, set-down slides, relocated set-downs), not a draw. The sessions are kept
  in ``$OBJSCAN_BENCH_SESSION_DIR`` when set (``bench/acquired_sessions.py``; a second run reuses them) and
  an object whose acquisition does not finish ``done`` (it ends ``failed`` at some view) is reported with
  its acquisition's status and left out of the table. Nothing of the reconstruct timing is measured here.

Which path made each row (``path`` in the JSON, ``ROW_PATHS``; ``label`` says it in words):

- ``fast``: the default static profile, then the fast pair registration (``DynamicConfig()``) in one
  configuration with the paper's chain (no_region ... region_crop), the pose-graph combination
  (``pose_graph``) or the automatic choice (``auto``, what ``objscan reconstruct`` runs).
- ``paper`` (``paper:<configuration>``): the same frames through the paper's own static
  profile (``StaticConfig.paper()``) and the paper's pair registration (``DynamicConfig.paper``: 5 attempts,
  4PCS at 0.9 / 0.85 / 0.8, colour ICP + GICP, the failure rule). To make them affordable without changing
  what they compute, the views' paper static registrations run one view per process and the pairs one per
  process (``$OBJSCAN_BENCH_WORKERS``, default: the core count, at least 2), and the paper static stage of a
  session is cached on disk next to the sessions (keyed by the frames and the static stage's source), so the
  four paper rows and a re-run reuse it. ``seconds`` is wall, ``cpu_s`` CPU of this process and its workers.
- ``oracle``: the default static profile's view clouds fused at their true poses (the noise floor).

``run(quick=True)``: milk, on ``realistic`` (drawn) and ``robot-turned`` (one physics acquisition, reused
from ``$OBJSCAN_BENCH_SESSION_DIR`` when there), rows no_region, pose_graph, auto, oracle and
paper:no_region. ``run()``: every HOPE object, the three profiles, every row (the four paper rows included);
``$OBJSCAN_BENCH_PAPER_OBJECTS`` (comma-separated) limits the paper rows to those objects (the paper pair
path costs seconds to tens of seconds per pair), ``$OBJSCAN_BENCH_OBJECTS`` and ``$OBJSCAN_BENCH_PROFILES``
(comma-separated) the objects and profiles (a partial run says so in its ``objects`` and ``profiles``);
``$OBJSCAN_BENCH_ROW_LOG`` appends each row as JSON lines as soon as it is measured.

Recorded sessions: with ``$OBJSCAN_BENCH_SESSIONS`` (comma-separated session folders of
``objscan scan``) only those sessions are measured (``physics_sessions``), rows as in ``--quick``.
"""

from __future__ import annotations

import os
import time

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

ROWS = ("no_region", "no_region_crop", "region", "region_crop", "pose_graph", "auto", "oracle")
# Paper-faithful rows: the paper's own static profile (``StaticConfig.paper()``: FPFH
# RANSAC, table removal, multi-scale colour ICP + GICP, overlap-only point-to-plane, pose graph) on the same
# frames, then the paper's pair registration (``DynamicConfig.paper``: 5 attempts, 4PCS at overlaps 0.9 /
# 0.85 / 0.8, multi-scale colour ICP + GICP, the failure rule, drop-lowest-fitness chain) in one
# configuration. ``paper:no_region`` etc.; every other row is the fast path on the default static profile.
PAPER_ROWS = tuple(f"paper:{c}" for c in ("no_region", "no_region_crop", "region", "region_crop"))
QUICK_ROWS = ("no_region", "pose_graph", "auto", "oracle", "paper:no_region")
SESSION_ROWS = QUICK_ROWS
ROW_LABELS = {
    **{r: f"fast path: default static profile, fast pairs, {r} configuration, paper chain" for r in ROWS[:4]},
    "pose_graph": "fast path: default static profile, fast pairs, no_region, pose-graph combination",
    "auto": "fast path: the default pipeline (automatic configuration choice), as objscan reconstruct",
    "oracle": "true-pose fusion of the default static profile's view clouds (sensor-noise floor)",
    **{r: f"paper-faithful: paper static profile, paper pairs (5 attempts, 4PCS), {r[6:]}, paper chain"
       for r in PAPER_ROWS},
}
ROW_PATHS = {**{r: "fast" for r in ROWS[:6]}, "oracle": "oracle", **{r: "paper" for r in PAPER_ROWS}}
DRAWN, PHYSICS = "drawn", "physics acquisition"
ACQUIRED_PROFILE = "robot-turned"  # the profile whose rows come from physics acquisitions
TURNS = {  # where a profile's turns between views come from
    "realistic": f"{DRAWN}: simulated_views, profile realistic (services/sim/profiles.py), no grasp",
    "hand-turned": f"{DRAWN}: simulated_views, profile hand-turned (services/sim/profiles.py), no grasp",
    ACQUIRED_PROFILE: f"{PHYSICS}: objscan scan --physics mujoco --profile robot-turned, the twin grasped, "
                      "turned and set the object down under MuJoCo contact",
}
PAPER = {  # the paper's Tables VI (hand) and VII (robot): inclusive / exclusive of the worst, mm; none for realistic
    "hand-turned": {"no_region": (4.94, 2.71), "no_region_crop": (3.67, 2.89), "region": (2.58, 2.42),
                    "region_crop": (3.18, 2.70)},
    "robot-turned": {"no_region": (2.26, 2.08), "no_region_crop": (5.44, 4.18), "region": (2.23, 2.01),
                     "region_crop": (2.97, 1.87)},
}


def workers() -> int:
    """Processes for the paper rows' static views and pairs: ``$OBJSCAN_BENCH_WORKERS`` or the cores (>= 2)."""
    named = os.environ.get("OBJSCAN_BENCH_WORKERS", "").strip()
    return max(int(named), 1) if named else max(os.cpu_count() or 1, 2)


def _cpu() -> float:
    """CPU seconds of this process and its reaped children (the pools' workers once shut down)."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ru.ru_utime + ru.ru_stime


def _views(obj: str, profile: str, seed: int):
    from bench.scenario import simulated_views

    frames = simulated_views(obj, views=12, scans_per_view=3, profile=profile, seed=seed)
    t0 = time.perf_counter()
    views = static_views(frames)
    return views, np.asarray(frames[0][0].meta["T_base_object_true"]), time.perf_counter() - t0, frames


def log_row(where: str, row: str, figures: dict) -> None:
    """Append one measured row to ``$OBJSCAN_BENCH_ROW_LOG`` (JSON lines) when set: a long run cut off on a
    loaded machine keeps the rows it finished (the JSON is written only at the end)."""
    path = os.environ.get("OBJSCAN_BENCH_ROW_LOG", "").strip()
    if not path:
        return
    import json

    line = {"where": where, "row": row, "t": time.strftime("%H:%M:%S", time.gmtime()),
            "load_average": [round(v, 2) for v in os.getloadavg()], **figures}
    with open(path, "a") as fh:
        fh.write(json.dumps(line, default=float) + "\n")


def _static_view(args: tuple) -> object:
    """One view through the static stage, as a dynamic view (module level: runs in a pool's worker)."""
    from services.registration.api import register_view, view_from_static

    fr, static, k, T_view0_view = args
    return view_from_static(register_view(fr, static), float(fr[0].meta.get("commanded_turn_deg", 30.0 * k)), k,
                            T_view0_view)


def static_views(frames: list, static=None, n_workers: int = 1) -> list:  # noqa: ANN001
    """The static stage (``static``: a ``StaticConfig``, default profile when None) on every view's frames,
    as dynamic views carrying their true motion from view 0 (for the oracle); ``n_workers`` > 1 runs the
    views in that many processes (the same function on the same frames: the same result)."""
    from common.geometry import invert

    def truth(fr) -> np.ndarray:  # noqa: ANN001
        return np.asarray(fr[0].meta["T_base_object_true"], dtype=float).reshape(4, 4)

    T0 = truth(frames[0])
    jobs = [(fr, static, k, T0 @ invert(truth(fr))) for k, fr in enumerate(frames)]
    if n_workers <= 1:
        return [_static_view(j) for j in jobs]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=n_workers) as pool:
        return list(pool.map(_static_view, jobs))


def _fingerprint(frames: list) -> str:
    """Hash of the frames' depth and colour and of the static stage's source: a cached paper static stage
    is reused only for the same frames through the same code."""
    import hashlib
    from pathlib import Path

    h = hashlib.sha1()
    for fr in frames:
        for f in fr:
            h.update(np.ascontiguousarray(f.depth).tobytes())
            h.update(np.ascontiguousarray(f.color).tobytes())
            h.update(np.asarray(f.T_base_camera, dtype=float).tobytes())
    reg = Path(__file__).resolve().parents[1] / "services" / "registration"
    for src in sorted(reg.rglob("*.py")):
        if "dynamic" not in src.relative_to(reg).parts:
            h.update(src.read_bytes())
    return h.hexdigest()[:16]


def paper_static(frames: list, cache_dir=None) -> tuple[list, dict]:  # noqa: ANN001
    """The paper static profile on every view (one view per worker process), and its timing; cached as a
    pickle in ``cache_dir`` (when given) under the frames' fingerprint, so the four paper rows of a session
    and a re-run pay for it once. Raises ``StaticRegistrationError`` as the stage does."""
    import pickle
    from pathlib import Path

    from services.registration.api import StaticConfig

    path = Path(cache_dir) / f"paper_static_{_fingerprint(frames)}.pkl" if cache_dir else None
    if path is not None and path.is_file():
        views, timing = pickle.loads(path.read_bytes())
        return views, {**timing, "static_cached": True}
    t, c = time.perf_counter(), _cpu()
    views = static_views(frames, StaticConfig.paper(), n_workers=workers())
    timing = {"static_s": time.perf_counter() - t, "static_cpu_s": _cpu() - c, "static_workers": workers()}
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps((views, timing)))
    return views, {**timing, "static_cached": False}


def paper_rows(frames: list, gt: np.ndarray, rows: tuple[str, ...], cache_dir=None,  # noqa: ANN001
               where: str = "") -> dict:
    """The paper-faithful rows of ``rows`` on these frames: paper static profile, then paper pairs (one pair
    per worker process; what each computes is unchanged)."""
    from services.registration.api import DynamicConfig, StaticRegistrationError, build_model, process_pool_map

    wanted = [r for r in rows if r in PAPER_ROWS]
    if not wanted:
        return {}
    try:
        views, timing = paper_static(frames, cache_dir)
    except StaticRegistrationError as exc:  # the paper's static stage can fail a view (e.g. no_table)
        return {r: {"error": exc.code, "label": ROW_LABELS[r], "path": ROW_PATHS[r]} for r in wanted}
    out = {}
    for row in wanted:
        t, c = time.perf_counter(), _cpu()
        m = build_model(views, DynamicConfig.paper(configuration=row[6:]), map_pairs=process_pool_map(workers()))
        out[row] = {"chamfer_mm": _chamfer(m.xyz, gt), "seconds": time.perf_counter() - t, "cpu_s": _cpu() - c,
                    "workers": workers(), **timing, "loop_rotation_deg": m.loop_closure["rotation_deg"],
                    "paths": [e.path for e in m.edges], "label": ROW_LABELS[row], "path": ROW_PATHS[row]}
        log_row(where, row, out[row])
    return out


def fast_row(views: list, gt: np.ndarray, row: str) -> dict:
    """One fast-path or oracle row (``ROW_PATHS``) on the default static profile's views."""
    from bench.synthetic import oracle_poses
    from services.registration.api import CombineConfig, DynamicConfig, build_model, fuse

    t, c = time.perf_counter(), _cpu()
    extra: dict = {}
    if row == "oracle":
        xyz = fuse(views, oracle_poses(views, gt), 0.001).xyz
    else:
        cfg = (DynamicConfig() if row == "auto" else
               DynamicConfig(configuration="no_region", combine=CombineConfig(method="pose_graph"))
               if row == "pose_graph" else DynamicConfig(configuration=row, combine=CombineConfig(method="paper")))
        m = build_model(views, cfg)
        xyz = m.xyz
        extra = {"configuration": m.configuration, "loop_rotation_deg": m.loop_closure["rotation_deg"],
                 "paths": [e.path for e in m.edges]}
    sec, cpu = time.perf_counter() - t, _cpu() - c
    return {"chamfer_mm": _chamfer(xyz, gt), "seconds": sec, "cpu_s": cpu, **extra, "label": ROW_LABELS[row],
            "path": ROW_PATHS[row]}


def _session_views(session):  # noqa: ANN001, ANN202
    """Views and ground truth of a finished acquisition's session folder (sim frames with true poses)."""
    from pathlib import Path

    from common.session_folder import read_scan
    from services.sim.catalogue import load_object

    session = Path(session)
    frames: list = []
    for k in range(12):
        try:
            frames.append([read_scan(session, k, j) for j in range(3)])
        except Exception:  # noqa: BLE001 - a view the session never captured ends the list
            break
    T0 = np.asarray(frames[0][0].meta["T_base_object_true"], dtype=float).reshape(4, 4)
    views = static_views(frames)
    m = frames[0][0].meta["object_model"]
    obj = load_object(m["source"] or m["name"], scale=m["scale"], up_axis=m["up_axis"])
    pts = obj.gt_points(60_000, seed=0)
    pts = pts[pts[:, 2] > 0.004]
    return views, pts @ T0[:3, :3].T + T0[:3, 3], frames[0][0].meta.get("physics", "geometric"), frames


def measure_session(session, rows: tuple[str, ...] = SESSION_ROWS, cache_dir=None) -> dict:  # noqa: ANN001
    """Chamfer (mm) and seconds per row on a recorded acquisition's frames (robot-turned for real: the
    twin grasped, turned and placed the object between views)."""
    views, gt, physics, frames = _session_views(session)
    out: dict = {"session": str(session), "views": len(views), "physics": physics,
                 "turns": f"{PHYSICS}: the session's frames ({physics})"}
    out.update(paper_rows(frames, gt, rows, cache_dir, where=str(session)))
    for row in (r for r in rows if r not in PAPER_ROWS):
        out[row] = fast_row(views, gt, row)
        log_row(str(session), row, out[row])
    if "auto" in out and "oracle" in out:
        out["auto_over_oracle"] = out["auto"]["chamfer_mm"] / out["oracle"]["chamfer_mm"]
    return out


def measure_acquired(obj: str, root, rows: tuple[str, ...], seed: int = 0) -> dict:  # noqa: ANN001
    """Every row on the physics acquisition of ``obj`` (made now, or reused from ``root``); an acquisition
    that did not finish ``done`` gives an error per row and its status."""
    from bench.acquired_sessions import acquire

    acq = acquire(obj, root, profile=ACQUIRED_PROFILE, physics="mujoco", seed=seed)
    if acq.status != "done":
        return {"acquisition": acq.to_json(), "turns": TURNS[ACQUIRED_PROFILE],
                **{r: {"error": f"acquisition_{acq.status}", "label": ROW_LABELS[r], "path": ROW_PATHS[r]}
                   for r in rows}}
    out = measure_session(acq.path, rows, cache_dir=root)
    if out["views"] < 12:
        raise RuntimeError(f"{acq.path}: a done acquisition with {out['views']} views")
    return {"acquisition": acq.to_json(), **out, "turns": TURNS[ACQUIRED_PROFILE]}


def _reconstruct_seconds(frames: list, workers: int, cpu: dict | None = None) -> float:
    """Wall time of the whole offline pipeline (``objscan reconstruct``) on these frames as a session folder;
    its CPU time (this process, all threads; not the workers') goes to ``cpu["s"]`` when given."""
    import tempfile
    from pathlib import Path

    from bench.scenario import write_session
    from services.registration.api import reconstruct

    with tempfile.TemporaryDirectory(prefix="bench-reconstruct-") as tmp:
        session = write_session(Path(tmp) / "session", frames)
        t0, c0 = time.perf_counter(), time.process_time()
        report = reconstruct(session, Path(tmp) / "out", workers=workers)
        seconds = time.perf_counter() - t0
        if cpu is not None:
            cpu["s"] = time.process_time() - c0
            cpu["global_fallbacks"] = sum(s.get("path") == "global" for v in report.get("views", [])
                                          for s in v.get("scans", [])[1:] if isinstance(s, dict))
    if "error" in (report.get("model") or {"error": "none"}):
        raise RuntimeError(f"reconstruct built no model: {report.get('model')}")
    return seconds


def _gt(obj: str, T0: np.ndarray) -> np.ndarray:
    from services.sim.catalogue import load_object

    pts = load_object(obj).gt_points(60_000, seed=0)
    pts = pts[pts[:, 2] > 0.004]
    return pts @ T0[:3, :3].T + T0[:3, 3]


def _chamfer(xyz: np.ndarray, gt: np.ndarray) -> float:
    """Chamfer after aligning the model to the ground truth as the paper does (ICP from identity)."""
    from services.registration.api import evaluate_model

    return float(evaluate_model(xyz, gt, align=True, init_T=np.eye(4))["chamfer_mm"])


def measure_object(obj: str, profile: str, seed: int = 0, rows: tuple[str, ...] = ROWS, cache_dir=None) -> dict:  # noqa: ANN001
    """Every row's Chamfer (mm) and seconds for one object and a drawn-turn profile."""
    views, T0, static_s, frames = _views(obj, profile, seed)
    gt = _gt(obj, T0)
    cores = max(os.cpu_count() or 1, 2)  # the pooled run always pools, to keep the comparison
    cpu: dict = {}
    out: dict = {"turns": TURNS[profile], "static_s": static_s,
                 "reconstruct_one_process_s": _reconstruct_seconds(frames, 1, cpu),
                 "reconstruct_pooled_s": _reconstruct_seconds(frames, cores), "reconstruct_workers": cores}
    out["reconstruct_one_process_cpu_s"] = cpu["s"]
    out["reconstruct_global_fallbacks"] = cpu["global_fallbacks"]
    out["reconstruct_s"] = min(out["reconstruct_one_process_s"], out["reconstruct_pooled_s"])
    out.update(paper_rows(frames, gt, rows, cache_dir, where=f"{obj} {profile}"))
    for row in (r for r in rows if r not in PAPER_ROWS):
        out[row] = fast_row(views, gt, row)
        log_row(f"{obj} {profile}", row, out[row])
    return out


def _table(per_object: dict[str, dict], rows: tuple[str, ...]) -> dict:
    table = {}
    for row in rows:
        measured = {o: r for o, r in per_object.items() if row in r}
        vals = {o: r[row]["chamfer_mm"] for o, r in measured.items() if "chamfer_mm" in r[row]}
        base = {"label": ROW_LABELS[row], "path": ROW_PATHS[row], "objects": sorted(measured)}
        if not vals:  # every object failed this row (e.g. the paper's static stage found no table)
            table[row] = {**base, "failed_objects": sorted(measured)}
            continue
        arr = np.array(list(vals.values()))
        worst = max(vals, key=vals.get)
        table[row] = {**base, "inclusive_mm": float(arr.mean()),
                      "exclusive_mm": float(np.mean([v for o, v in vals.items() if o != worst])) if len(vals) > 1
                      else float(arr.mean()),
                      "worst_object": worst,
                      "mean_seconds": float(np.mean([measured[o][row]["seconds"] for o in vals])),
                      "failed_objects": sorted(o for o in measured if o not in vals)}
    return table


def _rows_for(obj: str, rows: tuple[str, ...], paper_objects: set[str] | None) -> tuple[str, ...]:
    """``rows`` without the paper rows when ``paper_objects`` is given and ``obj`` is not in it."""
    if paper_objects is None or obj in paper_objects:
        return rows
    return tuple(r for r in rows if r not in PAPER_ROWS)


def _profile_summary(per_object: dict[str, dict], rows: tuple[str, ...], profile: str) -> dict:
    scored = {o: r for o, r in per_object.items() if "chamfer_mm" in r.get("auto", {})
              and "chamfer_mm" in r.get("oracle", {})}
    ratios = {o: r["auto"]["chamfer_mm"] / r["oracle"]["chamfer_mm"] for o, r in scored.items()}
    out = {"turns": TURNS[profile], "table": _table(per_object, rows), "paper": PAPER.get(profile, {}),
           "per_object": per_object, "auto_over_oracle": ratios,
           "auto_over_oracle_max": max(ratios.values()) if ratios else None,
           "auto_within_1_3x_on_every_object": bool(ratios) and all(v <= 1.3 for v in ratios.values()),
           "objects_not_scored": sorted(o for o in per_object if o not in scored)}
    recon = {o: r["reconstruct_s"] for o, r in per_object.items() if "reconstruct_s" in r}
    if recon:
        serial = {o: r["reconstruct_one_process_s"] for o, r in per_object.items()}
        pooled = {o: r["reconstruct_pooled_s"] for o, r in per_object.items()}
        out.update({
            "reconstruct_seconds": recon,
            "reconstruct_one_process_seconds": serial,
            "reconstruct_pooled_seconds": pooled,
            "reconstruct_pool_speedup": {o: serial[o] / pooled[o] for o in pooled},
            "reconstruct_seconds_max": max(recon.values()),
            "reconstruct_seconds_median": float(np.median(list(recon.values()))),
            "reconstruct_one_process_cpu_seconds": {o: r["reconstruct_one_process_cpu_s"]
                                                    for o, r in per_object.items()},
            "reconstruct_global_fallbacks": {o: r["reconstruct_global_fallbacks"] for o, r in per_object.items()},
            "reconstruct_within_20s": all(v <= 20.0 for v in recon.values()),
            "reconstruct_median_within_15s": float(np.median(list(recon.values()))) <= 15.0,
        })
    return out


def _env_list(name: str) -> list[str]:
    return [p.strip() for p in os.environ.get(name, "").split(",") if p.strip()]


def run(quick: bool = False) -> dict:
    """Measure; returns one JSON-able dict (per profile: where its turns come from, table, per-object
    figures, targets)."""
    import shutil
    import tempfile

    from bench.acquired_sessions import session_root
    from services.sim.catalogue import hope_names

    sessions = _env_list("OBJSCAN_BENCH_SESSIONS")
    if sessions:
        return {"physics_sessions": [measure_session(p) for p in sessions]}
    objects = _env_list("OBJSCAN_BENCH_OBJECTS") or (["milk"] if quick else hope_names())
    profiles = _env_list("OBJSCAN_BENCH_PROFILES") or (
        ["realistic", ACQUIRED_PROFILE] if quick else ["realistic", "hand-turned", ACQUIRED_PROFILE])
    unknown = [p for p in profiles if p not in TURNS]
    if unknown:
        raise ValueError(f"OBJSCAN_BENCH_PROFILES: unknown {unknown}; known: {sorted(TURNS)}")
    rows = QUICK_ROWS if quick else ROWS + PAPER_ROWS
    paper_objects = set(_env_list("OBJSCAN_BENCH_PAPER_OBJECTS")) or None
    tmp = tempfile.mkdtemp(prefix="objscan-bench-dynamic-")
    root = session_root(tmp)
    result: dict = {"quick": quick, "objects": objects, "rows": list(rows), "row_paths": ROW_PATHS,
                    "paper_objects": sorted(paper_objects) if paper_objects else objects,
                    "session_dir": str(root) if str(root) != tmp else None, "workers": workers(), "profiles": {}}
    try:
        for profile in profiles:
            if profile == ACQUIRED_PROFILE:
                per_object = {o: measure_acquired(o, root, _rows_for(o, rows, paper_objects)) for o in objects}
            else:
                per_object = {o: measure_object(o, profile, seed=0, rows=_rows_for(o, rows, paper_objects),
                                                cache_dir=root / f"{o}_{profile}_seed0_static") for o in objects}
            result["profiles"][profile] = _profile_summary(per_object, rows, profile)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return result


def main() -> None:
    import json
    import sys

    res = run(quick="--quick" in sys.argv)
    for profile, p in res.get("profiles", {}).items():
        print(f"\n{profile}  [{p['turns']}]  (Chamfer in mm after alignment to the GT; paper values for reference)")
        print(f"{'row':16s} {'path':6s} {'incl':>7s} {'excl':>7s} {'worst':>14s} {'sec':>7s}   paper incl/excl")
        for row, t in p["table"].items():
            if "inclusive_mm" not in t:
                print(f"{row:16s} {t['path']:6s} failed on {t['failed_objects']}")
                continue
            paper = p["paper"].get(row.removeprefix("paper:"))
            ps = f"{paper[0]:.2f}/{paper[1]:.2f}" if paper else ""
            print(f"{row:16s} {t['path']:6s} {t['inclusive_mm']:7.3f} {t['exclusive_mm']:7.3f} "
                  f"{t['worst_object']:>14s} {t['mean_seconds']:7.1f}   {ps}")
        print("auto / oracle:", {o: round(v, 3) for o, v in p["auto_over_oracle"].items()},
              "within 1.3x:", p["auto_within_1_3x_on_every_object"], "not scored:", p["objects_not_scored"])
        for o, r in p["per_object"].items():
            if "acquisition" in r:
                a = r["acquisition"]
                how = "reused" if a["reused"] else f"acquired in {a['seconds']} s"
                print(f"  {o}: acquisition {a['status']} ({a['views']} views, {how}) {a['path']}")
        if "reconstruct_seconds" in p:
            print("objscan reconstruct s:", {o: round(v, 1) for o, v in p["reconstruct_seconds"].items()},
                  "within 20 s:", p["reconstruct_within_20s"],
                  "one process s:", {o: round(v, 1) for o, v in p["reconstruct_one_process_seconds"].items()})
    if "--json" in sys.argv:
        print(json.dumps(res, indent=2, default=float))


if __name__ == "__main__":
    main()

"""Per-edge yaw error of the dynamic stage's pair registration against the twin's truth.

Why: on textured cylinders (alphabet_soup, tomato_sauce) the loop of 12 pair transforms does not close
(14-17 deg), so the automatic choice runs all four configurations. This measures where that comes from,
edge by edge: for a recorded session (``objscan bench reconstruct`` keeps them with
``$OBJSCAN_BENCH_SESSION_DIR``), the static stage isolates each view (cached as a pickle next to the session,
the static stage is not what is measured here), then every pair of one configuration is registered and its
transform compared with the true one.

Truth: the twin's own record. A view's cloud is in ``base`` as scan 0's *believed* camera pose puts it
(the static stage's frame), so its true pose in view 0's object-fixed frame is
``O_k = B0 Bk^-1 C_k C'_k^-1`` (B: the object's true pose, C / C': scan 0's true / believed camera pose):
the camera's per-scan and hand-eye errors the static clouds carry are in the truth. (The "oracle" row's
per-view fit on the mesh, ``bench.synthetic.oracle_poses``, leaves a cylinder's yaw free and is not used
here.) Edge s -> t's true transform in the stacked frame is ``S_t O_t^-1 O_s S_s^-1`` (S: the view's
pre-rotation); the yaw error is the signed angle about the turn axis of ``R_est R_true^T``, the translation
error the displacement of the object centre.

``python -m bench.pair_yaw SESSION [SESSION ...] [--configuration no_region] [--no-yaw-refine] [--json F]``;
a SESSION ``synthetic:NAME[:SEED]`` uses ``bench.synthetic`` views of a HOPE object instead (realistic turn
draws, no static stage, exact view poses: quick, for objects without a recorded session)
(``--no-yaw-refine``: the fast path as it was before the yaw search, for before / after figures)
"""

from __future__ import annotations

import json
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np


def session_views(session: Path) -> tuple[list, np.ndarray]:
    """(dynamic views with their true motion, ground-truth points in view 0's base) of a recorded session;
    the static stage's output is cached in ``SESSION/dynamic_views.pkl``."""
    from bench.dynamic import _gt, static_views
    from common.session_folder import SESSION_FILE, read_scan

    session = Path(session)
    cache = session / "dynamic_views.pkl"
    meta = json.loads((session / SESSION_FILE).read_text())
    name = meta.get("object")
    frames = None
    if cache.is_file():
        views = pickle.loads(cache.read_bytes())
    else:
        frames = [[read_scan(session, k, j) for j in range(3)] for k in range(len(meta["views"]))]
        views = static_views(frames)
        cache.write_bytes(pickle.dumps(views))
    T0 = _truth(session)
    return views, _gt(name, T0)


def _meta(session: Path, k: int) -> dict:
    return json.loads((session / f"view_{k:02d}" / "scan_0" / "meta.json").read_text())


def _truth(session: Path, k: int = 0) -> np.ndarray:
    return np.asarray(_meta(session, k)["T_base_object_true"], dtype=float).reshape(4, 4)


def true_view_poses(session: Path, n: int) -> list[np.ndarray]:
    """``O_k``: view k's cloud (scan 0's believed frame) into view 0's ``base``, from the twin's record."""
    import ast

    out = []
    B0 = _truth(session, 0)
    for k in range(n):
        m = _meta(session, k)
        gt = m["ground_truth"]
        gt = ast.literal_eval(gt) if isinstance(gt, str) else gt
        C = np.asarray(gt["T_base_camera"], dtype=float).reshape(4, 4)
        Cb = np.asarray(m["T_base_camera"] if not isinstance(m["T_base_camera"], str)
                        else json.loads(m["T_base_camera"]), dtype=float).reshape(4, 4)
        out.append(true_view_pose(B0, _truth(session, k), C, Cb))
    return out


def true_view_pose(B0: np.ndarray, Bk: np.ndarray, C_true: np.ndarray, C_believed: np.ndarray) -> np.ndarray:
    """``O_k = B0 Bk^-1 C C'^-1``: view k's cloud (in ``base`` as scan 0's believed camera pose ``C'`` puts it;
    ``C`` the true one) into view 0's ``base``, where B0 / Bk are the object's true poses in views 0 / k."""
    return B0 @ np.linalg.inv(Bk) @ C_true @ np.linalg.inv(C_believed)


def true_edges(prep: Any, oracle: list[np.ndarray]) -> dict[tuple[int, int], np.ndarray]:
    """True transform of every neighbour edge (source -> target) in the stacked frame."""
    from services.registration.api import neighbour_edges

    S = {pv.index: pv.T_stack_view for pv in prep.views}
    out = {}
    for s, t in neighbour_edges(len(prep.views)):
        out[(s, t)] = S[t] @ np.linalg.inv(oracle[t]) @ oracle[s] @ np.linalg.inv(S[s])
    return out


def edge_error(T: np.ndarray, T_true: np.ndarray, axis: np.ndarray, center: np.ndarray) -> dict[str, float]:
    """Signed yaw error (deg) about ``axis``, tilt error (deg) and centre displacement error (mm)."""
    from common.geometry import yaw_deg_about
    from services.registration.api import tilt_deg

    dR = np.asarray(T)[:3, :3] @ np.asarray(T_true)[:3, :3].T
    c = np.asarray(center, dtype=float)
    dc = (T[:3, :3] @ c + T[:3, 3]) - (T_true[:3, :3] @ c + T_true[:3, 3])
    E = np.eye(4)
    E[:3, :3] = dR
    return {"yaw_err_deg": yaw_deg_about(axis, dR), "tilt_err_deg": tilt_deg(E, axis),
            "trans_err_mm": 1000.0 * float(np.linalg.norm(dc))}


def measure(session: Path, configuration: str = "no_region", pair: Any = None) -> dict[str, Any]:
    """Every edge of ``configuration`` on a recorded ``session`` against the twin's record."""
    views, _ = session_views(session)
    return {"session": str(session), **measure_views(views, true_view_poses(Path(session), len(views)),
                                                     configuration, pair)}


def measure_synthetic(name: str, seed: int = 0, configuration: str = "no_region", pair: Any = None) -> dict[str, Any]:
    """The same on ``bench.synthetic`` views (realistic turn draws, no static stage: exact view poses)."""
    from bench.synthetic import synthetic_views

    views = synthetic_views(name, views=12, scans_per_view=3, profile="realistic", seed=seed).views
    return {"session": f"synthetic:{name}:{seed}",
            **measure_views(views, [np.asarray(v.T_view0_view_true) for v in views], configuration, pair)}


def measure_views(views: list, poses: list[np.ndarray], configuration: str = "no_region",
                  pair: Any = None) -> dict[str, Any]:
    """Every edge of ``configuration``: its error against the true view poses, path, fitness, CPU s."""
    from services.registration.api import (
        CONFIGURATIONS,
        DynamicConfig,
        attach_regions,
        chain_to_first,
        loop_closure_error,
        make_pair_jobs,
        preprocess,
        register_pair,
    )

    cfg = DynamicConfig()
    prep = preprocess(views, cfg.preprocess)
    regions, crop = CONFIGURATIONS[configuration]
    if regions:
        attach_regions(prep, cfg.preprocess)
    truth = true_edges(prep, poses)
    jobs = make_pair_jobs(prep, replace(pair or cfg.pair, regions=regions, crop=crop))
    c0 = time.process_time()
    results = [register_pair(j) for j in jobs[:-1]]
    jobs[-1].prior = np.linalg.inv(chain_to_first(results))
    results.append(register_pair(jobs[-1]))
    cpu = time.process_time() - c0
    edges = []
    for r in results:
        e = edge_error(np.asarray(r.T), truth[(r.source_view, r.target_view)], prep.axis, prep.center)
        prior_e = edge_error(np.asarray(jobs[r.index].prior), truth[(r.source_view, r.target_view)],
                             prep.axis, prep.center)
        edges.append({"edge": f"{r.source_view}->{r.target_view}", **{k: round(v, 3) for k, v in e.items()},
                      "prior_yaw_err_deg": round(prior_e["yaw_err_deg"], 2), "path": r.path,
                      "fitness": round(r.fitness, 3), "color_fitness": round(r.color_fitness, 3),
                      "seconds": round(r.seconds, 2)})
    yaw = np.array([e["yaw_err_deg"] for e in edges])
    loop = loop_closure_error(results, prep.center)
    return {"configuration": configuration, "pairs_cpu_s": round(cpu, 2),
            "abs_yaw_err_deg_median": round(float(np.median(np.abs(yaw))), 3),
            "abs_yaw_err_deg_max": round(float(np.abs(yaw).max()), 3),
            "yaw_err_sum_chain_deg": round(float(yaw[:-1].sum()), 2),
            "loop_rotation_deg": round(float(loop["rotation_deg"]), 2),
            "loop_translation_mm": round(float(loop["translation_mm"]), 2), "edges": edges}


def main() -> None:
    args = sys.argv[1:]
    conf = "no_region"
    out_json = None
    if "--configuration" in args:
        i = args.index("--configuration")
        conf = args[i + 1]
        del args[i:i + 2]
    if "--json" in args:
        i = args.index("--json")
        out_json = args[i + 1]
        del args[i:i + 2]
    pair = None
    if "--no-yaw-refine" in args:
        from services.registration.api import PairConfig, YawRefineConfig

        args.remove("--no-yaw-refine")
        pair = PairConfig(yaw_refine=YawRefineConfig(enabled=False))
    rows = []
    for s in args:
        r = (measure_synthetic(s.split(":")[1], int(s.split(":")[2]) if s.count(":") > 1 else 0, conf, pair)
             if s.startswith("synthetic:") else measure(Path(s), conf, pair))
        rows.append(r)
        print(f"{Path(s).name} [{conf}]: |yaw err| median {r['abs_yaw_err_deg_median']} max "
              f"{r['abs_yaw_err_deg_max']} deg, chain sum {r['yaw_err_sum_chain_deg']} deg, loop "
              f"{r['loop_rotation_deg']} deg / {r['loop_translation_mm']} mm, pairs {r['pairs_cpu_s']} CPU-s")
        for e in r["edges"]:
            print(f"   {e['edge']:>6} yaw {e['yaw_err_deg']:+7.2f} (prior {e['prior_yaw_err_deg']:+7.2f}) tilt "
                  f"{e['tilt_err_deg']:5.2f} trans {e['trans_err_mm']:6.2f} mm {e['path']:>8} f {e['fitness']:.3f} "
                  f"cf {e['color_fitness']:.3f} {e['seconds']:.2f}s")
    if out_json:
        Path(out_json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()

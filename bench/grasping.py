"""``objscan bench grasping``: the paper's grasp Tables I-V and its 30-degree rotation figures, on the twin
with MuJoCo contact physics (``services/sim/physics.py``).

Per HOPE object, 7 initial poses (standing at yaw 0/45/90 deg, lying on a side at yaw 0/60 deg, lying on
an end or the other side at yaw 0/60 deg; each let come to rest by the physics first), each method
(frontal, top-down) makes one attempt per pose as the paper did: 3 D435-like frames around the object
(twin, ``robot-turned`` camera errors), static registration isolates the object, the grasp planner runs
in that mode, and the top-ranked grasp is executed: the pads open to the planned width + 40 mm at the
grasp pose, close, lift 40 mm (physics decides: held, slipped out, or never gripped). A held object is
turned by the planner's 30-degree turn pose and set down (physics: where it lands).

Columns (paper III-B): ``grasps`` successful grasps, ``slips`` grasps that closed on the object and lost
it while lifting, ``avg_rank`` mean GeoGrasp rank of the top grasp (attempts that had one), ``avg_grasp``
mean number of grasps generated, ``grasp_rate`` grasps / attempts.
Tables: I frontal, all poses; II frontal, the tallest poses only (resting height within 5 mm of the
object's tallest); III frontal "360": one chain of 12 grasp-turn-set-down steps from the tallest pose,
each step re-scanning wherever the object was left (the paper's subset: orange juice,
tomato sauce); IV top-down, all poses; V top-down 360 (milk, alphabet soup, as the paper). ``--quick``: 3 poses,
4-step chains for every object. ``$OBJSCAN_BENCH_OBJECTS`` (comma-separated), ``$OBJSCAN_BENCH_POSES``
and ``$OBJSCAN_BENCH_CHAIN`` narrow a run; ``$OBJSCAN_BENCH_WORKERS`` runs objects in parallel processes.
``rotation[method]``: ``success_rate`` share of held grasps whose turn and set-down left the object
resting as it was grasped (up axis within 20 deg: not overturned), ``mean_degree_change`` mean |yaw change|
of the object over those set-downs (``standing``: the same over turns that started standing); the
paper's "average degree change" after a commanded 30 deg is 41.5-44.1 frontal, 26.0-32.2 top-down.

Not modelled (say so beside the figures): the arm's reach and motion planning (the paper's MoveIt
failures); an attempt fails here only on grasping. The approach is checked geometrically (pads against
the table and the object), the contact by physics.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from dataclasses import replace
from typing import Any

import numpy as np

from common.geometry import make_transform, rotation_about_axis

WORKSPACE_XY = (0.60, 0.0)
OPEN_MARGIN = 0.04  # m beyond the planned width, as the orchestrator opens (TurnMotion.open_margin)
TALLEST_TOL = 0.005
METHODS = ("frontal", "top_down")
#: The paper's tables for the objects both have (HOPE names; the paper's short names in comments).
PAPER = {
    "I": {"milk": (3, 3, 7.965, 1.50, 0.50), "tomato_sauce": (3, 0, 8.568, 1.33, 0.50),
          "cream_cheese": (4, 3, 5.753, 1.11, 0.44)},
    "II": {"milk": (3, 2, 7.706, 2.00, 1.00), "tomato_sauce": (3, 0, 8.568, 2.00, 1.00),
           "cream_cheese": (4, 2, 5.753, 1.11, 0.66)},
    "III": {"orange_juice": (9, 4, 7.620, 2.00, 0.90), "tomato_sauce": (8, 1, 8.106, 2.00, 0.88)},
    "IV": {"milk": (3, 2, 8.032, 1.50, 0.50), "tomato_sauce": (4, 1, 7.346, 1.50, 0.66),
           "cream_cheese": (6, 0, 6.899, 1.44, 0.66)},
    "V": {"milk": (8, 3, 7.255, 1.50, 0.66), "alphabet_soup": (10, 1, 7.636, 2.00, 0.83)},
}
PAPER_ROTATION = {"frontal": {"success_rate": 0.89, "mean_degree_change": [41.5, 44.1]},
                  "top_down": {"success_rate": 0.89, "mean_degree_change": [26.0, 32.2]}}


def initial_orientations() -> list[tuple[str, np.ndarray]]:
    """(name, rotation) of the 7 start poses in the object frame: standing, on a side, on an end."""
    Rz = [rotation_about_axis([0, 0, 1], np.radians(a)) for a in (0.0, 45.0, 60.0, 90.0)]
    Rx = rotation_about_axis([1, 0, 0], np.pi / 2)
    Ry = rotation_about_axis([0, 1, 0], np.pi / 2)
    return [("standing_0", Rz[0]), ("standing_45", Rz[1]), ("standing_90", Rz[3]),
            ("side_0", Rx), ("side_60", Rz[2] @ Rx), ("end_0", Ry), ("end_60", Rz[2] @ Ry)]


def resting_pose(world_obj, scene, R: np.ndarray, xy=WORKSPACE_XY) -> np.ndarray:  # noqa: ANN001
    """T_base_object with rotation ``R`` put 2 mm above the table at ``xy`` and let come to rest."""
    v = world_obj.vertices @ R.T
    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
    T = make_transform(R, [xy[0] - c[0], xy[1] - c[1], 0.002 - v[:, 2].min()])
    return scene.settle(T, seconds=1.0)


def resting_height(obj, T: np.ndarray) -> float:  # noqa: ANN001
    return float((obj.vertices @ T[:3, :3].T + T[:3, 3])[:, 2].max())


def scan_and_plan(world, method: str, seq: int):  # noqa: ANN001, ANN201
    """3 frames around the object as it lies, the static registration's isolated object, the plan."""
    from bench.scenario import ScanPoses
    from services.grasp import plan_grasps
    from services.grasp.service import GraspService
    from services.registration.api import register_view

    T = world.true_object_pose()
    top = resting_height(world.obj, T)
    box = world.obj.vertices @ T[:3, :3].T + T[:3, 3]
    center = np.r_[0.5 * (box[:, :2].min(axis=0) + box[:, :2].max(axis=0)), top / 2]
    frames = [world.render_frame(Tc, None, seq + j, stamp=(seq + j) / 30.0)
              for j, Tc in enumerate(ScanPoses().poses(center, 3))]
    view = register_view(frames)
    cfg = replace(GraspService.planner_config(grasp_depth=0.01), mode=method)
    return plan_grasps(view.object_cloud.xyz, view.object_cloud.normals, view.table, cfg)


def attempt(world, method: str, seq: int) -> dict[str, Any]:  # noqa: ANN001
    """One scan-plan-grasp(-turn-set-down) on ``world`` as it stands; the world is left where physics
    put the object."""
    try:
        plan = scan_and_plan(world, method, seq)
    except Exception as exc:  # noqa: BLE001 - an object the registration cannot isolate is a failed attempt
        return {"generated": 0, "rank": None, "held": False, "reason": f"scan_failed:{type(exc).__name__}"}
    out: dict[str, Any] = {"generated": len(plan.grasps), "rank": None, "held": False, "reason": "no_grasp"}
    if not plan.grasps:
        return out
    g = plan.grasps[0]
    out["rank"] = float(g.rank)
    T_grasp, T_turn = g.poses["grasp"], g.poses.get("turn")
    world.set_gripper_opening(min(g.width + OPEN_MARGIN, world.gripper.max_opening))
    before = world.true_object_pose()
    result = world.close_gripper(T_grasp, 0.0)
    out.update(held=bool(result.success), reason=result.reason)
    if not result.success:
        world.open_gripper()
        return out
    if T_turn is None:
        world.open_gripper()
        return out
    lift = np.eye(4)
    lift[2, 3] = 0.02
    world.move_gripper(lift @ T_grasp)
    world.move_gripper(lift @ T_turn)
    world.move_gripper(T_turn)
    world.open_gripper()
    out["turn"] = turn_figures(before, world.true_object_pose())
    return out


def turn_figures(before: np.ndarray, after: np.ndarray) -> dict[str, Any]:
    """How the object moved from before the grasp to rest after the set-down: ``degree_change`` its turn
    about the table normal, ``upright_kept`` whether the side that was up is still up (within 20 deg)."""
    Rd = after[:3, :3] @ before[:3, :3].T
    up_in_object = before[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    return {"degree_change": abs(float(np.degrees(np.arctan2(Rd[1, 0] - Rd[0, 1], Rd[0, 0] + Rd[1, 1])))),
            "upright_kept": bool((after[:3, :3] @ up_in_object)[2] > np.cos(np.radians(20.0)))}


def _row(name: str, attempts: list[dict[str, Any]]) -> dict[str, Any]:
    ranks = [a["rank"] for a in attempts if a["rank"] is not None]
    grasps = sum(a["held"] for a in attempts)
    return {"object": name, "attempts": len(attempts), "grasps": grasps,
            "slips": sum(a["reason"] == "slip" for a in attempts),
            "avg_rank": float(np.mean(ranks)) if ranks else None,
            "avg_grasp": float(np.mean([a["generated"] for a in attempts])) if attempts else 0.0,
            "grasp_rate": grasps / len(attempts) if attempts else 0.0,
            "reasons": sorted({a["reason"] for a in attempts if not a["held"]})}


#: Objects of the 360 chains in the full run: the paper's Tables III (frontal) and V (top-down) subsets.
CHAIN_OBJECTS = {"frontal": ("orange_juice", "tomato_sauce"), "top_down": ("milk", "alphabet_soup")}


def object_results(name: str, n_poses: int | None, chain_steps: int, chains: dict[str, tuple[str, ...]] | None,
                   seed: int = 0) -> dict[str, Any]:
    """Every attempt on one object: per method, the attempts per start pose and the 360 chain (when the
    object is in ``chains[method]``, or always when ``chains`` is None)."""
    from services.sim.catalogue import load_object
    from services.sim.world import World

    t0 = time.time()
    obj = load_object(name)
    probe = World(obj, physics="mujoco", seed=seed)
    poses = [(pname, resting_pose(obj, probe._physics, R)) for pname, R in initial_orientations()[:n_poses]]
    heights = {pname: resting_height(obj, T) for pname, T in poses}
    out: dict[str, Any] = {"heights_m": heights}
    for method in METHODS:
        results = {}
        for i, (pname, T) in enumerate(poses):
            w = World(obj, profile="robot-turned", physics="mujoco", seed=seed + i, object_pose=T)
            results[pname] = attempt(w, method, seq=100 * i)
        out[method] = results
        chain = []
        if chains is None or name in chains.get(method, ()):
            start = max(poses, key=lambda pt: heights[pt[0]])[1]  # the tallest pose, then wherever it lies
            w = World(obj, profile="robot-turned", physics="mujoco", seed=seed + 50, object_pose=start)
            chain = [attempt(w, method, seq=1000 + 10 * k) for k in range(chain_steps)]
        out[f"{method}_360"] = chain
        print(f"grasping: {name} {method}: {sum(r['held'] for r in results.values())}/{len(results)} held, "
              f"360 chain {sum(a['held'] for a in chain)}/{len(chain)} ({time.time() - t0:.0f} s)",
              file=sys.stderr, flush=True)
    return out


def aggregate(per_object: dict[str, Any]) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """Tables I-V and the rotation figures from every object's attempts (``object_results``).

    A turn succeeds when the set-down leaves the object resting as it was grasped (its up axis within 20
    deg of where it was: not overturned); the degree change is the object's yaw change over those. Lying
    cans can roll, which shows as large yaw changes, so ``standing`` repeats the figures over the turns
    that started standing (the standing poses and the 360 chains), closest to what the paper turned.
    """
    tables: dict[str, list[dict[str, Any]]] = {k: [] for k in ("I", "II", "III", "IV", "V")}
    turns: dict[str, list[tuple[bool, dict[str, Any]]]] = {m: [] for m in METHODS}
    for name, res in per_object.items():
        tallest = max(res["heights_m"].values())
        tall = [p for p, h in res["heights_m"].items() if h >= tallest - TALLEST_TOL]
        tables["I"].append(_row(name, list(res["frontal"].values())))
        tables["II"].append(_row(name, [res["frontal"][p] for p in tall]))
        tables["IV"].append(_row(name, list(res["top_down"].values())))
        for method, key in (("frontal", "III"), ("top_down", "V")):
            if res[f"{method}_360"]:
                tables[key].append(_row(name, res[f"{method}_360"]))
            for pose, a in res[method].items():
                if "turn" in a:
                    turns[method].append((pose.startswith("standing"), a["turn"]))
            turns[method] += [(True, a["turn"]) for a in res[f"{method}_360"] if "turn" in a]
    rotation: dict[str, Any] = {}
    for method, ts in turns.items():
        def figures(sel: list[dict[str, Any]]) -> dict[str, Any]:
            ok = [t for t in sel if t["upright_kept"]]
            return {"turns": len(sel), "success_rate": len(ok) / len(sel) if sel else 0.0,
                    "mean_degree_change": float(np.mean([t["degree_change"] for t in ok])) if ok else None,
                    "overturned": len(sel) - len(ok)}
        rotation[method] = {**figures([t for _, t in ts]), "standing": figures([t for st, t in ts if st])}
    return tables, rotation


def run(quick: bool = False) -> dict[str, Any]:
    """All HOPE objects (``$OBJSCAN_BENCH_WORKERS`` processes, default 1: one object each at a time)."""
    from concurrent.futures import ProcessPoolExecutor

    from services.sim.catalogue import hope_names

    t0 = time.time()
    names = [n for n in hope_names() if n in os.environ.get("OBJSCAN_BENCH_OBJECTS", n).split(",")]
    n_poses = int(os.environ.get("OBJSCAN_BENCH_POSES", 3 if quick else 7))
    chain_steps = int(os.environ.get("OBJSCAN_BENCH_CHAIN", 4 if quick else 12))
    chains = None if quick else CHAIN_OBJECTS
    workers = max(1, int(os.environ.get("OBJSCAN_BENCH_WORKERS", "1")))
    args = [(n, n_poses, chain_steps, chains) for n in names]
    if workers > 1:
        # spawn, not fork: the parent has open3d's threads running, and a forked child can deadlock on them
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            per_object = dict(zip(names, pool.map(object_results, *zip(*args, strict=True)), strict=True))
    else:
        per_object = {n: object_results(*a) for n, a in zip(names, args, strict=True)}
    tables, rotation = aggregate(per_object)
    return {"physics": "mujoco", "quick": quick, "objects": names,
            "poses": [p for p, _ in initial_orientations()[:n_poses]], "chain_steps": chain_steps,
            "chain_objects": {m: list(v) for m, v in (chains or {m: tuple(names) for m in METHODS}).items()},
            "tables": tables, "rotation": rotation,
            "paper": {"tables": {k: {o: dict(zip(("grasps", "slips", "avg_rank", "avg_grasp", "grasp_rate"), v,
                                                 strict=True)) for o, v in rows.items()} for k, rows in PAPER.items()},
                      "rotation": PAPER_ROTATION},
            "per_object": per_object, "seconds": time.time() - t0}


def main(quick: bool = False) -> None:
    import json

    print(json.dumps(run(quick=quick), indent=2, default=float))


if __name__ == "__main__":
    main()

"""The peer of ``bench reconstruct``: Open3D's multiway-registration tutorial pipeline, written from its API.

What the tutorial does, step by step, and what this peer does with it:

1. each point cloud downsampled on a voxel grid, normals estimated (radius 2 voxels, 30 neighbours);
2. every pair (s, t), s < t: point-to-plane ICP coarse (max correspondence 15 voxels) then fine (1.5
   voxels), and the information matrix of the fine result;
3. a pose graph: the chain of consecutive pairs (odometry) gives each node's pose and a certain edge, every
   other pair a loop-closure edge marked uncertain;
4. Levenberg-Marquardt global optimisation (correspondence 1.5 voxels, edge prune threshold 0.25,
   reference node 0);
5. the clouds transformed by their optimised poses, concatenated and downsampled (fusion).

The tutorial's scenes are consecutive frames of a moving camera, so it starts every pair from identity and
uses a 2 cm voxel for rooms. Here the clouds are an object turned ~30 degrees between views, so the voxel is
scaled to objects (``VOXEL`` = 2 mm: coarse 30 mm, fine 3 mm) and each pair starts from the same prior
objscan's dynamic stage has: the commanded turn about the table normal through each view's object centre.

**Its input** (all of it from the same session and the same ``objscan reconstruct`` run, so the peer is
compared on exactly what the dynamic stage gets): the static stage's isolated object cloud of each view
(``OUT/views/view_KK.ply``: the view's scans registered, table and background removed, in ``base``), each
view's object centre and table normal (``OUT/report.json``) and the commanded cumulative turns
(``SESSION/session.json``). The peer does not isolate the object itself; ``bench reconstruct`` adds the
static stage's wall (which produced that input) to the peer's own wall in ``peer_seconds``.

Run as a process (``python -m bench.multiway_peer OUT SESSION MODEL``) so that its wall includes its
imports as objscan's CLI wall does; it writes the fused model to MODEL and prints its figures as JSON.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from common.session_folder import REPORT_FILE, SESSION_FILE

VOXEL = 0.002  # m: the tutorial's voxel scaled from rooms to objects
COARSE = 15 * VOXEL  # the tutorial's coarse and fine correspondence distances, in voxels
FINE = 1.5 * VOXEL
FUSION_VOXEL = 0.001  # the fused model's grid, as objscan's model and the true-pose fusion
reg = o3d.pipelines.registration


def _turn_about(axis: np.ndarray, point: np.ndarray, deg: float) -> np.ndarray:
    """Rotation by ``deg`` about the line through ``point`` along ``axis`` (a 4x4 transform)."""
    R = o3d.geometry.get_rotation_matrix_from_axis_angle(np.asarray(axis, float) / np.linalg.norm(axis)
                                                         * np.radians(deg))
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = point - R @ point
    return T


def prior_poses(centers: list[np.ndarray], normals: list[np.ndarray], turns_deg: list[float]) -> list[np.ndarray]:
    """Each view's prior pose in view 0's frame: the commanded turn undone about the view's vertical axis,
    then its centre moved onto view 0's (``T_view0_viewk``)."""
    out = []
    for c, n, turn in zip(centers, normals, turns_deg, strict=True):
        T = _turn_about(n, c, -(turn - turns_deg[0]))
        T[:3, 3] += centers[0] - c
        out.append(T)
    return out


def _prepare(pcd: o3d.geometry.PointCloud) -> o3d.geometry.PointCloud:
    down = pcd.voxel_down_sample(VOXEL)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * VOXEL, max_nn=30))
    return down


def pairwise(source: o3d.geometry.PointCloud, target: o3d.geometry.PointCloud,
             init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Point-to-plane ICP coarse then fine from ``init``: (source -> target transform, information matrix)."""
    p2l = reg.TransformationEstimationPointToPlane()
    coarse = reg.registration_icp(source, target, COARSE, init, p2l)
    fine = reg.registration_icp(source, target, FINE, coarse.transformation, p2l)
    T = np.asarray(fine.transformation)
    return T, np.asarray(reg.get_information_matrix_from_point_clouds(source, target, FINE, T))


def multiway(clouds: list[o3d.geometry.PointCloud], priors: list[np.ndarray]) -> list[np.ndarray]:
    """The tutorial's full registration and global optimisation: each cloud's pose in cloud 0's frame."""
    graph = reg.PoseGraph()
    odometry = np.eye(4)
    graph.nodes.append(reg.PoseGraphNode(odometry))
    n = len(clouds)
    for s in range(n):
        for t in range(s + 1, n):
            T, info = pairwise(clouds[s], clouds[t], np.linalg.inv(priors[t]) @ priors[s])
            if t == s + 1:  # odometry: the chain gives the next node's pose
                odometry = T @ odometry
                graph.nodes.append(reg.PoseGraphNode(np.linalg.inv(odometry)))
                graph.edges.append(reg.PoseGraphEdge(s, t, T, info, uncertain=False))
            else:  # loop closure
                graph.edges.append(reg.PoseGraphEdge(s, t, T, info, uncertain=True))
    option = reg.GlobalOptimizationOption(max_correspondence_distance=FINE, edge_prune_threshold=0.25,
                                          reference_node=0)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                reg.GlobalOptimizationConvergenceCriteria(), option)
    return [np.asarray(node.pose) for node in graph.nodes]


def run_peer(out: Path, session: Path, model: Path) -> dict[str, Any]:
    """Register and fuse the views of one ``objscan reconstruct`` output; write the model; its figures."""
    t0 = time.perf_counter()
    report = json.loads((out / REPORT_FILE).read_text())
    turns = {int(v["index"]): float(v.get("commanded_turn_deg", 0.0))
             for v in json.loads((session / SESSION_FILE).read_text())["views"]}
    items = {int(v["index"]): v for v in report.get("views", []) if "error" not in v and v.get("ply")}
    order = sorted(items)
    full = [o3d.io.read_point_cloud(str(out / items[k]["ply"])) for k in order]
    normals = [np.asarray(items[k]["table"]["normal"], float) for k in order]
    centers = [np.asarray(items[k]["object_center"], float) for k in order]
    priors = prior_poses(centers, normals, [turns[k] for k in order])
    t1 = time.perf_counter()
    poses = multiway([_prepare(c) for c in full], priors)
    t2 = time.perf_counter()
    fused = o3d.geometry.PointCloud()
    for cloud, T in zip(full, poses, strict=True):
        fused += o3d.geometry.PointCloud(cloud).transform(T)
    fused = fused.voxel_down_sample(FUSION_VOXEL)
    model.parent.mkdir(parents=True, exist_ok=True)
    o3d.io.write_point_cloud(str(model), fused)
    t3 = time.perf_counter()
    return {"views": order, "pairs": len(order) * (len(order) - 1) // 2, "points": len(fused.points),
            "load_s": round(t1 - t0, 3), "registration_s": round(t2 - t1, 3), "fusion_s": round(t3 - t2, 3),
            "voxel_m": VOXEL, "poses": [np.round(T, 8).tolist() for T in poses]}


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 3:
        print("usage: python -m bench.multiway_peer RECONSTRUCT_OUT SESSION MODEL_PLY", file=sys.stderr)
        return 2
    print(json.dumps(run_peer(Path(args[0]), Path(args[1]), Path(args[2]))))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The peer of ``bench reconstruct``: an Open3D-tutorial pipeline from the session's raw frames, independent of
objscan (it imports nothing of objscan's: only Open3D and NumPy).

What a user of Open3D's tutorials writes to get one model out of an objscan session folder
(``view_KK/scan_J/{color,depth}.png`` + ``meta.json`` with the arm's believed camera pose; ``session.json`` with
each view's commanded turn), step by step:

1. **Per view, a fragment** (the reconstruction system's "make fragments", the RGBD-image tutorial): each scan's
   colour and depth read as an ``RGBDImage``; scans 1.. registered to scan 0 by RGB-D odometry (the odometry
   tutorial: hybrid term, default ``OdometryOption``) from the arm's relative pose; each scan's point cloud
   (``create_from_rgbd_image``) put in ``base`` by scan 0's arm pose and its odometry, concatenated.
2. **Per view, the object** (the point-cloud tutorial): a crop around where the arm looks (an axis-aligned box
   about scan 0's centre-pixel point, from just under the table up), voxel down-sampling, the table removed as
   the dominant RANSAC plane (``segment_plane``), the largest DBSCAN cluster kept.
3. **The multiway-registration tutorial** on the view objects: normals (radius 2 voxels, 30 neighbours); every
   pair point-to-plane ICP coarse (15 voxels) then fine (1.5 voxels) from the arm's prior (the commanded turn
   about the table normal through each view's object centre) and its information matrix; odometry edges along
   the chain, loop closures (uncertain) for the rest; Levenberg-Marquardt global optimisation (correspondence
   1.5 voxels, edge prune threshold 0.25, reference node 0).
4. **Fusion**: every view object by its optimised pose, concatenated and down-sampled to 1 mm.

The tutorial's numbers are for rooms (2 cm voxel, 1 cm plane distance); here they are scaled to objects by one
voxel, ``VOXEL`` = 2 mm (plane distance 2.5 voxels, DBSCAN eps 5 voxels). The views are processed on a thread
per core (Open3D releases the GIL, as objscan's static stage does); Open3D keeps its own default threading.

Run as a process (``python -m bench.multiway_peer SESSION MODEL``) so that its wall includes its imports as
objscan's CLI wall does; it writes the fused model to MODEL and prints its figures as JSON.
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

VOXEL = 0.002  # m: the tutorial's voxel scaled from rooms to objects
COARSE = 15 * VOXEL  # the tutorial's coarse and fine correspondence distances, in voxels
FINE = 1.5 * VOXEL
PLANE_DISTANCE = 2.5 * VOXEL  # segment_plane's inlier distance (the tutorial's 1 cm, scaled)
PLANE_ITERATIONS = 1000  # the tutorial's
DBSCAN_EPS = 5 * VOXEL
DBSCAN_MIN_POINTS = 10  # the tutorial's
CROP_HALF_WIDTH = 0.15  # m: the crop's half width about where the arm looks (objects are < 10 cm across)
CROP_BELOW, CROP_ABOVE = 0.02, 0.35  # m below / above the table top (z = 0 in base)
DEPTH_TRUNC = 1.2  # m: farther is background
FUSION_VOXEL = 0.001  # the fused model's grid, as objscan's model and the true-pose fusion
reg = o3d.pipelines.registration


# ------------------------------------------------------------------------------------ the session's raw frames


def read_scan(folder: Path) -> tuple[o3d.geometry.RGBDImage, o3d.camera.PinholeCameraIntrinsic, np.ndarray, float]:
    """One scan folder: (RGBD image, intrinsics, the arm's believed T_base_camera, depth scale)."""
    meta = json.loads((folder / "meta.json").read_text())
    k = meta["intrinsics"]
    intrinsic = o3d.camera.PinholeCameraIntrinsic(k["width"], k["height"], k["fx"], k["fy"], k["cx"], k["cy"])
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.io.read_image(str(folder / "color.png")), o3d.io.read_image(str(folder / "depth.png")),
        depth_scale=1.0 / float(meta["depth_scale"]), depth_trunc=DEPTH_TRUNC, convert_rgb_to_intensity=False)
    return rgbd, intrinsic, np.asarray(meta["T_base_camera"], dtype=float).reshape(4, 4), float(meta["depth_scale"])


def _gray(rgbd: o3d.geometry.RGBDImage) -> o3d.geometry.RGBDImage:
    """The intensity + depth image the odometry takes (the colour one keeps its colour for the cloud)."""
    depth = np.asarray(rgbd.depth)
    color = o3d.geometry.Image(np.ascontiguousarray((np.asarray(rgbd.color)).astype(np.uint8)))
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        color, o3d.geometry.Image(np.ascontiguousarray(depth)), depth_scale=1.0, depth_trunc=DEPTH_TRUNC,
        convert_rgb_to_intensity=True)


def centre_point(rgbd: o3d.geometry.RGBDImage, intrinsic: o3d.camera.PinholeCameraIntrinsic,
                 T_base_camera: np.ndarray) -> np.ndarray:
    """Where the camera looks, in base: the centre pixel's point (median depth of a 15 px window)."""
    depth = np.asarray(rgbd.depth)
    cx, cy = intrinsic.get_principal_point()
    u, v = int(round(cx)), int(round(cy))
    win = depth[v - 7:v + 8, u - 7:u + 8]
    z = float(np.median(win[win > 0])) if (win > 0).any() else 0.5
    return (T_base_camera @ np.array([0.0, 0.0, z, 1.0]))[:3]


# ------------------------------------------------------------------------------------ per view


def fragment(view: Path) -> tuple[o3d.geometry.PointCloud, np.ndarray]:
    """The view's scans in one cloud in base (RGB-D odometry to scan 0 from the arm's relative pose), and the
    point scan 0 looks at."""
    scans = [read_scan(d) for d in sorted(view.glob("scan_*")) if (d / "meta.json").is_file()]
    rgbd0, intrinsic, T0, _ = scans[0]
    gray0 = _gray(rgbd0)
    option = o3d.pipelines.odometry.OdometryOption()
    jacobian = o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()
    cloud = o3d.geometry.PointCloud()
    for k, (rgbd, _, T, _) in enumerate(scans):
        T_c0_ck = np.eye(4)
        if k > 0:
            prior = np.linalg.inv(T0) @ T
            ok, T_odo, _ = o3d.pipelines.odometry.compute_rgbd_odometry(_gray(rgbd), gray0, intrinsic, prior,
                                                                         jacobian, option)
            T_c0_ck = np.asarray(T_odo) if ok else prior
        cloud += o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, intrinsic).transform(T0 @ T_c0_ck)
    return cloud, centre_point(rgbd0, intrinsic, T0)


def isolate(cloud: o3d.geometry.PointCloud, look_at: np.ndarray) -> tuple[o3d.geometry.PointCloud, np.ndarray]:
    """The object of one view fragment: crop, down-sample, table plane out, largest cluster (and the plane's
    upward normal)."""
    lo = np.array([look_at[0] - CROP_HALF_WIDTH, look_at[1] - CROP_HALF_WIDTH, -CROP_BELOW])
    hi = np.array([look_at[0] + CROP_HALF_WIDTH, look_at[1] + CROP_HALF_WIDTH, CROP_ABOVE])
    down = cloud.crop(o3d.geometry.AxisAlignedBoundingBox(lo, hi)).voxel_down_sample(VOXEL)
    plane, inliers = down.segment_plane(distance_threshold=PLANE_DISTANCE, ransac_n=3,
                                        num_iterations=PLANE_ITERATIONS)
    normal = np.asarray(plane[:3], dtype=float)
    normal = normal if normal[2] >= 0 else -normal
    objects = down.select_by_index(inliers, invert=True)
    labels = np.asarray(objects.cluster_dbscan(eps=DBSCAN_EPS, min_points=DBSCAN_MIN_POINTS))
    if labels.size and labels.max() >= 0:
        largest = np.bincount(labels[labels >= 0]).argmax()
        objects = objects.select_by_index(np.flatnonzero(labels == largest))
    return objects, normal / np.linalg.norm(normal)


def view_object(view: Path) -> tuple[o3d.geometry.PointCloud, np.ndarray]:
    cloud, look_at = fragment(view)
    return isolate(cloud, look_at)


# ------------------------------------------------------------------------------------ multiway registration


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


def run_peer(session: Path, model: Path, threads: int | None = None) -> dict[str, Any]:
    """The whole peer on one session folder: per-view objects, multiway registration, fusion into MODEL."""
    t0 = time.perf_counter()
    views = json.loads((session / "session.json").read_text())["views"]
    order = sorted(int(v["index"]) for v in views if (session / f"view_{int(v['index']):02d}").is_dir())
    turns = {int(v["index"]): float(v.get("commanded_turn_deg", 0.0)) for v in views}
    with ThreadPoolExecutor(max_workers=threads or os.cpu_count() or 1) as pool:
        isolated = list(pool.map(view_object, [session / f"view_{k:02d}" for k in order]))
    objects = [obj for obj, _ in isolated]
    centers = [np.asarray(obj.get_center()) for obj in objects]
    priors = prior_poses(centers, [n for _, n in isolated], [turns[k] for k in order])
    t1 = time.perf_counter()
    poses = multiway([_prepare(c) for c in objects], priors)
    t2 = time.perf_counter()
    fused = o3d.geometry.PointCloud()
    for cloud, T in zip(objects, poses, strict=True):
        fused += o3d.geometry.PointCloud(cloud).transform(T)
    fused = fused.voxel_down_sample(FUSION_VOXEL)
    model.parent.mkdir(parents=True, exist_ok=True)
    o3d.io.write_point_cloud(str(model), fused)
    t3 = time.perf_counter()
    return {"views": order, "pairs": len(order) * (len(order) - 1) // 2, "points": len(fused.points),
            "views_s": round(t1 - t0, 3), "registration_s": round(t2 - t1, 3), "fusion_s": round(t3 - t2, 3),
            "voxel_m": VOXEL, "poses": [np.round(T, 8).tolist() for T in poses]}


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m bench.multiway_peer SESSION MODEL_PLY", file=sys.stderr)
        return 2
    print(json.dumps(run_peer(Path(args[0]), Path(args[1]))))
    return 0


if __name__ == "__main__":
    sys.exit(main())

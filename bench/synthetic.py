"""Simulated dynamic-stage input: 12 isolated views of a HOPE object, virtually scanned (tests, benchmarks).

A stand-in for ``bench/scenario.py`` + the static stage, so the dynamic pipeline can be tested
and benchmarked on its own. It uses the twin's notions: the HOPE object as ``services/sim/catalogue.py``
loads it (footprint centre at (0.36, 0, 0), z up, its texture sampled as the twin does), the twin's error
profile for the turns and set-down shifts (``services/sim/profiles.py``: the draws of ``World.turn_object``;
each shift is about the nominal spot here, where the twin accumulates them)
and the D435 colour model (``common.messages.d435_intrinsics``). It ray-casts three scans per view from the
robot side (depth noise growing with range, 1 mm depth quantisation, a per-view exposure change), drops
points near the table as the static stage's plane removal does, fuses the scans at 1 mm and estimates
normals and a (deliberately naive, visible-side-biased) object centre. Ground truth (true object pose per
view and the object) rides along for evaluation only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.geometry import invert, look_at, make_transform, rotation_about_axis
from common.messages import Plane, d435_intrinsics
from services.registration.api import DynamicRegistrationError, DynamicView, to_o3d
from services.sim.catalogue import SimObject, load_object
from services.sim.errors import SimError
from services.sim.profiles import get_profile

OBJECT_POSITION = np.array([0.36, 0.0, 0.0])
TABLE_CUT_M = 0.004  # the static stage removes points within a few mm of the table plane


def surface_samples(obj: SimObject, n: int, seed: int = 0, min_z: float = TABLE_CUT_M) -> np.ndarray:
    """Uniform surface samples (object frame), without the footprint no camera can see."""
    pts = obj.gt_points(int(n * 1.3), seed=seed)
    return pts[pts[:, 2] > min_z][:n]


def scan_camera_poses(distance: float = 0.36, heights: tuple[float, ...] = (0.22, 0.30, 0.22),
                      azimuths_deg: tuple[float, ...] = (-25.0, 0.0, 25.0),
                      target_z: float = 0.07) -> list[np.ndarray]:
    """T_base_camera of the three scan poses: on the robot side of the object, looking at it."""
    poses = []
    for h, az in zip(heights, azimuths_deg, strict=True):
        a = np.radians(180.0 + az)  # the robot stands at -x of the object
        eye = OBJECT_POSITION + np.array([distance * np.cos(a), distance * np.sin(a), h])
        poses.append(look_at(eye, OBJECT_POSITION + [0.0, 0.0, target_z]))
    return poses


def raycast_scan(mesh: SimObject, T_base_object: np.ndarray, T_base_camera: np.ndarray,
                 rng: np.random.Generator, width: int = 640, height: int = 480,
                 exposure: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """One D435-like depth+color scan of the object, back-projected to ``base``: (xyz, rgb)."""
    verts = mesh.vertices @ T_base_object[:3, :3].T + T_base_object[:3, 3]
    T_cam_base = invert(T_base_camera)
    vc = verts @ T_cam_base[:3, :3].T + T_cam_base[:3, 3]
    K = d435_intrinsics(width, height)
    fx, cx, cy = K.fx, K.cx, K.cy
    uv = vc[:, :2] / vc[:, 2:3] * fx + [cx, cy]
    u0, v0 = np.clip(np.floor(uv.min(0)).astype(int) - 2, 0, [width - 1, height - 1])
    u1, v1 = np.clip(np.ceil(uv.max(0)).astype(int) + 2, 0, [width - 1, height - 1])
    uu, vv = np.meshgrid(np.arange(u0, u1 + 1), np.arange(v0, v1 + 1))
    dirs_cam = np.column_stack([(uu.ravel() - cx) / fx, (vv.ravel() - cy) / fx, np.ones(uu.size)])
    dirs = dirs_cam @ T_base_camera[:3, :3].T
    origins = np.broadcast_to(T_base_camera[:3, 3], dirs.shape)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(verts.astype(np.float32)),
                        o3d.core.Tensor(mesh.triangles.astype(np.uint32)))
    rays = o3d.core.Tensor(np.hstack([origins, dirs]).astype(np.float32))
    hit = scene.cast_rays(rays)
    t = hit["t_hit"].numpy()
    ok = np.isfinite(t)
    depth = t[ok]  # dirs have unit z in the camera frame, so t is the depth
    # D435-like noise: grows with the square of the range; then 1 mm quantisation (depth_scale 0.001)
    sigma = 0.0003 + 0.0012 * (depth / 0.5) ** 2
    depth = np.round((depth + rng.normal(0.0, 1.0, depth.size) * sigma) * 1000.0) / 1000.0
    pts_cam = dirs_cam[ok] * depth[:, None]
    xyz = pts_cam @ T_base_camera[:3, :3].T + T_base_camera[:3, 3]
    prim = hit["primitive_ids"].numpy()[ok].astype(np.int64)
    albedo = mesh.surface_colors(prim, hit["primitive_uvs"].numpy()[ok])
    rgb = np.clip(albedo.astype(np.float64) * exposure + rng.normal(0, 2.0, (len(prim), 3)),
                  0, 255).astype(np.uint8)
    return xyz, rgb


@dataclass
class SyntheticScan:
    """The simulated views plus their ground truth (for evaluation only)."""

    object_name: str
    profile: str
    views: list[DynamicView]
    mesh: SimObject
    T_base_object_true: list[np.ndarray]

    def gt_points_view0(self, n: int = 100_000, seed: int = 0) -> np.ndarray:
        """Ground-truth surface samples placed where the object stood in view 0 (``base``)."""
        pts = surface_samples(self.mesh, n, seed=seed)
        T = self.T_base_object_true[0]
        return pts @ T[:3, :3].T + T[:3, 3]


def synthetic_views(object_name: str, views: int = 12, scans_per_view: int = 3,
                    profile: str = "hand-turned", seed: int = 0, voxel: float = 0.001,
                    turn_deg: float | None = None) -> SyntheticScan:
    """Virtually scan a HOPE object turned ``views`` times by ~360/views degrees (or ``turn_deg`` each:
    two views 30 degrees apart make one pair for a test).

    Returns isolated, fused, normal-carrying views in ``base`` with their commanded cumulative turn,
    a table plane z = 0 and a naive centre estimate (centroid of the visible side), like the static
    stage's output; plus the true object pose per view.
    """
    try:
        prof = get_profile(profile)
        mesh = load_object(object_name)
    except SimError as exc:  # an unknown profile or object
        raise DynamicRegistrationError(exc.message, code="bad_value", detail=exc.detail) from None
    rng = np.random.default_rng(seed)
    gain = prof.draw_turn_gain(rng)
    cams = scan_camera_poses()[:scans_per_view] if scans_per_view <= 3 else scan_camera_poses(
        heights=tuple(np.linspace(0.2, 0.32, scans_per_view)),
        azimuths_deg=tuple(np.linspace(-30, 30, scans_per_view)))
    step = 360.0 / views if turn_deg is None else float(turn_deg)
    yaw_true = 0.0
    position = OBJECT_POSITION.copy()
    table = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=OBJECT_POSITION.copy())
    out_views: list[DynamicView] = []
    poses: list[np.ndarray] = []
    for k in range(views):
        if k > 0:  # the twin's set-down draw (World.turn_object): achieved turn, footprint shift
            achieved, shift, _ = prof.draw_set_down(step, gain, rng)
            yaw_true += achieved
            # put back on its mark: the shift is about the nominal spot, not accumulated as on the twin's table
            position[:2] = OBJECT_POSITION[:2] + shift
        T_bo = make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_true)), position.copy())
        poses.append(T_bo)
        exposure = float(rng.uniform(0.92, 1.08))
        parts = [raycast_scan(mesh, T_bo, cam, rng, exposure=exposure) for cam in cams]
        xyz = np.vstack([p[0] for p in parts])
        rgb = np.vstack([p[1] for p in parts])
        keep = xyz[:, 2] > TABLE_CUT_M
        pcd = to_o3d(xyz[keep], rgb[keep]).voxel_down_sample(voxel)
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.006, max_nn=30))
        eye = np.mean([c[:3, 3] for c in cams], axis=0)
        pcd.orient_normals_towards_camera_location(eye)
        pts = np.asarray(pcd.points)
        centroid = pts.mean(0)
        center = np.array([centroid[0], centroid[1], 0.5 * (pts[:, 2].max() + 0.0)])
        out_views.append(DynamicView(
            xyz=pts.astype(np.float32), rgb=(np.asarray(pcd.colors) * 255).round().astype(np.uint8),
            normals=np.asarray(pcd.normals).astype(np.float32), table=table, center=center,
            commanded_turn_deg=step * k, index=k, T_view0_view_true=poses[0] @ invert(T_bo),
            meta={"true_turn_deg": yaw_true, "object": object_name, "profile": profile}))
    return SyntheticScan(object_name, profile, out_views, mesh, poses)


def oracle_poses(views: list[DynamicView], gt_points: np.ndarray,
                 max_corr: tuple[float, ...] = (0.006, 0.003, 0.0015)) -> list[np.ndarray]:
    """Per-view poses that put each view's cloud best onto the ground truth (evaluation only).

    Starts from the true object motion (``T_view0_view_true``) and refines each view alone against the
    ground-truth points with point-to-point ICP. The static stage's clouds carry the camera's hand-eye
    and joint errors, so the true object motion alone is *not* the best fusion of them; the per-view fit
    is: fusing with these poses is the sensor-noise floor (the "oracle") a registration is compared with.
    """
    reg = o3d.pipelines.registration
    gt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(gt_points, dtype=np.float64)))
    out = []
    for v in views:
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(v.xyz, dtype=np.float64)))
        src = src.voxel_down_sample(0.002)
        T = np.asarray(v.T_view0_view_true if v.T_view0_view_true is not None else np.eye(4), dtype=float)
        for d in max_corr:
            T = np.asarray(reg.registration_icp(src, gt, d, T, reg.TransformationEstimationPointToPoint(),
                                                reg.ICPConvergenceCriteria(max_iteration=50)).transformation)
        out.append(T)
    return out

"""Simulated dynamic-stage input: 12 isolated views of a HOPE object, virtually scanned.

A stand-in for ``services/sim/scenario.py`` + the static stage, so the dynamic pipeline can be tested
and benchmarked on its own. It places the textured HOPE mesh on the table as the conventions say
(footprint centre at (0.36, 0, 0), z up), turns it 30° per view with the profile's turn errors and
placement slide, ray-casts three D435-like scans per view from the robot side (depth noise growing with
range, 1 mm depth quantisation, texture colors with a per-view exposure change), drops points near the
table as the static stage's plane removal does, fuses the scans at 1 mm and estimates normals and a
(deliberately naive, visible-side-biased) object centre. Ground truth (true object pose per view and
the mesh) rides along for evaluation only.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import open3d as o3d
from PIL import Image

from common.geometry import invert, look_at, make_transform, rotation_about_axis
from common.messages import Plane
from services.registration.dynamic.views import DynamicRegistrationError, DynamicView

HOPE_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "hope"
OBJECT_POSITION = np.array([0.36, 0.0, 0.0])
TABLE_CUT_M = 0.004  # the static stage removes points within a few mm of the table plane


@dataclass(frozen=True)
class TurnProfile:
    """How the object is actually turned between views (errors the registration must absorb)."""

    turn_error_low_deg: float
    turn_error_high_deg: float
    slide_sigma_m: float


PROFILES = {
    # a person turns it: close to 30°, placed back nearly in place
    "hand-turned": TurnProfile(-5.0, 5.0, 0.002),
    # the gripper turns it: the paper saw systematic over-turning and slips (41.5° average for 30°)
    "robot-turned": TurnProfile(-5.0, 15.0, 0.005),
}


def _parse_obj(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, triangles, per-corner uvs) of a triangulated OBJ, read directly.

    Read by hand because open3d's reader re-orders texture coordinates on these files (sampled
    colors came out wrong); the format is simple: ``v``, ``vt`` and ``f v/vt[/vn]`` lines.
    """
    verts, tex, faces, face_uv = [], [], [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                verts.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("vt "):
                tex.append([float(x) for x in line.split()[1:3]])
            elif line.startswith("f "):
                corners = [c.split("/") for c in line.split()[1:]]
                for a, b in ((1, 2), (2, 3)) if len(corners) == 4 else ((1, 2),):
                    tri = (corners[0], corners[a], corners[b])
                    faces.append([int(c[0]) - 1 for c in tri])
                    face_uv.append([int(c[1]) - 1 if len(c) > 1 and c[1] else -1 for c in tri])
    v = np.asarray(verts, dtype=np.float64)
    t = np.asarray(tex, dtype=np.float64) if tex else np.zeros((1, 2))
    fuv = np.asarray(face_uv)
    uvs = np.where(fuv[..., None] >= 0, t[np.clip(fuv, 0, None)], 0.0)
    return v, np.asarray(faces, dtype=np.int32), uvs


@dataclass
class TexturedMesh:
    """A HOPE mesh in the ``object`` frame: metres, z up, footprint centre at the origin."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int32
    triangle_uvs: np.ndarray  # (T, 3, 2) float64
    texture: np.ndarray  # (H, W, 3) uint8

    def o3d_mesh(self) -> o3d.geometry.TriangleMesh:
        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(self.vertices),
                                      o3d.utility.Vector3iVector(self.triangles))
        m.compute_vertex_normals()
        return m

    def sample_surface(self, n: int, seed: int = 0, min_z: float = TABLE_CUT_M) -> np.ndarray:
        """Uniform surface samples (object frame), without the footprint no camera can see."""
        pcd = self.o3d_mesh().sample_points_uniformly(number_of_points=int(n * 1.3), seed=seed) \
            if _has_seed_arg() else self.o3d_mesh().sample_points_uniformly(number_of_points=int(n * 1.3))
        pts = np.asarray(pcd.points)
        return pts[pts[:, 2] > min_z][:n]


@lru_cache(maxsize=1)
def _has_seed_arg() -> bool:
    import inspect

    try:
        return "seed" in inspect.signature(o3d.geometry.TriangleMesh.sample_points_uniformly).parameters
    except (TypeError, ValueError):
        return False


def hope_objects() -> list[str]:
    """Names of the HOPE objects present in shared/data (empty if the data is absent)."""
    if not HOPE_DIR.is_dir():
        return []
    return sorted(p.name for p in HOPE_DIR.iterdir() if p.is_dir() and list(p.glob("*.obj")))


@lru_cache(maxsize=8)
def load_hope_mesh(name: str) -> TexturedMesh:
    """Load ``shared/data/hope/<name>``: centimetres -> metres, y up -> z up, bottom at z = 0."""
    folder = HOPE_DIR / name
    objs = sorted(folder.glob("*.obj")) if folder.is_dir() else []
    if not objs:
        raise DynamicRegistrationError(f"HOPE mesh {name!r} not found", code="no_data",
                                       detail={"path": str(folder)})
    v, tri, uvs = _parse_obj(objs[0])
    v = v * 0.01
    v = np.column_stack([v[:, 0], -v[:, 2], v[:, 1]])  # +90° about x: y (long axis) becomes z
    lo, hi = v.min(0), v.max(0)
    v -= np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    pngs = sorted(folder.glob("*.png"))
    tex = np.asarray(Image.open(pngs[0]).convert("RGB")) if pngs else np.full((2, 2, 3), 180, np.uint8)
    return TexturedMesh(name, v, tri, uvs, tex)


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


def raycast_scan(mesh: TexturedMesh, T_base_object: np.ndarray, T_base_camera: np.ndarray,
                 rng: np.random.Generator, width: int = 640, height: int = 480, fx: float = 615.0,
                 exposure: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """One D435-like depth+color scan of the mesh, back-projected to ``base``: (xyz, rgb)."""
    verts = mesh.vertices @ T_base_object[:3, :3].T + T_base_object[:3, 3]
    T_cam_base = invert(T_base_camera)
    vc = verts @ T_cam_base[:3, :3].T + T_cam_base[:3, 3]
    cx, cy = width / 2.0, height / 2.0
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
    bary = hit["primitive_uvs"].numpy()[ok].astype(np.float64)
    tuv = mesh.triangle_uvs[prim]
    w = np.column_stack([1.0 - bary.sum(1), bary[:, 0], bary[:, 1]])
    tex_uv = (tuv * w[:, :, None]).sum(1)
    H, W = mesh.texture.shape[:2]
    px = np.clip((tex_uv[:, 0] % 1.0) * W, 0, W - 1).astype(int)
    py = np.clip((1.0 - tex_uv[:, 1] % 1.0) * H, 0, H - 1).astype(int)
    rgb = np.clip(mesh.texture[py, px].astype(np.float64) * exposure + rng.normal(0, 2.0, (len(px), 3)),
                  0, 255).astype(np.uint8)
    return xyz, rgb


@dataclass
class SyntheticScan:
    """The simulated views plus their ground truth (for evaluation only)."""

    object_name: str
    profile: str
    views: list[DynamicView]
    mesh: TexturedMesh
    T_base_object_true: list[np.ndarray]

    def gt_points_view0(self, n: int = 100_000, seed: int = 0) -> np.ndarray:
        """Ground-truth surface samples placed where the object stood in view 0 (``base``)."""
        pts = self.mesh.sample_surface(n, seed=seed)
        T = self.T_base_object_true[0]
        return pts @ T[:3, :3].T + T[:3, 3]


def synthetic_views(object_name: str, views: int = 12, scans_per_view: int = 3,
                    profile: str = "hand-turned", seed: int = 0, voxel: float = 0.001) -> SyntheticScan:
    """Virtually scan a HOPE object turned ``views`` times by ~360/views degrees.

    Returns isolated, fused, normal-carrying views in ``base`` with their commanded cumulative turn,
    a table plane z = 0 and a naive centre estimate (centroid of the visible side), like the static
    stage's output; plus the true object pose per view.
    """
    if profile not in PROFILES:
        raise DynamicRegistrationError(f"unknown profile {profile!r}", code="bad_value",
                                       detail={"profiles": sorted(PROFILES)})
    prof = PROFILES[profile]
    rng = np.random.default_rng(seed)
    mesh = load_hope_mesh(object_name)
    cams = scan_camera_poses()[:scans_per_view] if scans_per_view <= 3 else scan_camera_poses(
        heights=tuple(np.linspace(0.2, 0.32, scans_per_view)),
        azimuths_deg=tuple(np.linspace(-30, 30, scans_per_view)))
    step = 360.0 / views
    yaw_true = 0.0
    table = Plane(normal=np.array([0.0, 0.0, 1.0]), offset=0.0, center=OBJECT_POSITION.copy())
    out_views: list[DynamicView] = []
    poses: list[np.ndarray] = []
    for k in range(views):
        if k > 0:
            yaw_true += step + rng.uniform(prof.turn_error_low_deg, prof.turn_error_high_deg)
        slide = np.r_[rng.normal(0.0, prof.slide_sigma_m, 2), 0.0] if k > 0 else np.zeros(3)
        T_bo = make_transform(rotation_about_axis([0, 0, 1], np.radians(yaw_true)), OBJECT_POSITION + slide)
        poses.append(T_bo)
        exposure = float(rng.uniform(0.92, 1.08))
        parts = [raycast_scan(mesh, T_bo, cam, rng, exposure=exposure) for cam in cams]
        xyz = np.vstack([p[0] for p in parts])
        rgb = np.vstack([p[1] for p in parts])
        keep = xyz[:, 2] > TABLE_CUT_M
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz[keep]))
        pcd.colors = o3d.utility.Vector3dVector(rgb[keep] / 255.0)
        pcd = pcd.voxel_down_sample(voxel)
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

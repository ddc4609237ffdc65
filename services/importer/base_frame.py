"""A ``base`` frame for a fixed camera, from the table plane it sees.

An arm session knows each camera pose in the arm's ``base`` (z up, table top at z = 0). A fixed camera
knows nothing, so ``base`` is made from what it sees: z = the table's normal (found by the same
prior-driven search as the static stage, ``static.table.segment_table``, with "up" taken as the image's up
direction within ``max_tilt_deg``: a camera looking across or down at the table), the origin where the
image centre's point (the object) stands on the table, x along the viewing direction projected on the
table. The table is fitted on several frames together, so the object never hides the same part of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.geometry import invert, make_transform
from common.messages import RGBDFrame
from services.importer.errors import ImportError_
from services.registration.api import NoTableError, StaticConfig, centre_depth, frame_points, segment_table

#: optical frame (x right, y down, z forward): an upright camera's "up" is -y
IMAGE_UP = (0.0, -1.0, 0.0)


@dataclass(frozen=True)
class BaseFrameConfig:
    """How the table is looked for in the camera's frame."""

    camera_up: tuple[float, float, float] = IMAGE_UP  # the world's up as seen by the camera, roughly
    max_tilt_deg: float = 60.0  # a camera may look down on the table by up to this much
    frames_used: int = 5  # frames (evenly spread) whose points are pooled to fit the table
    voxel: float = 0.004  # m; the pooled cloud is thinned to this

    def __post_init__(self) -> None:
        if not 0 < self.max_tilt_deg < 90:
            raise ValueError(f"max_tilt_deg must be in (0, 90), got {self.max_tilt_deg}")
        if np.linalg.norm(self.camera_up) < 1e-9 or self.frames_used < 1:
            raise ValueError("camera_up must be non-zero and frames_used at least 1")


@dataclass
class BaseFrame:
    """``T_base_camera`` of the fixed camera and the figures of the table it came from."""

    T_base_camera: np.ndarray
    table_normal_cam: np.ndarray
    table_offset_cam: float
    camera_height_m: float  # above the table
    look_down_deg: float  # angle of the optical axis below the table plane
    table_fraction: float

    def to_json(self) -> dict:
        return {"T_base_camera": self.T_base_camera.tolist(), "table_normal_camera": self.table_normal_cam.tolist(),
                "table_offset_camera_m": self.table_offset_cam, "camera_height_m": round(self.camera_height_m, 4),
                "look_down_deg": round(self.look_down_deg, 2), "table_fraction": round(self.table_fraction, 4)}


def estimate_base_frame(frames: list[RGBDFrame], config: BaseFrameConfig | None = None,
                        static: StaticConfig | None = None) -> BaseFrame:
    """The fixed camera's pose in a table-based ``base``; ``ImportError_`` (``no_table``) when no plane fits."""
    cfg = config or BaseFrameConfig()
    st = static or StaticConfig()
    picks = np.unique(np.linspace(0, len(frames) - 1, min(cfg.frames_used, len(frames))).round().astype(int))
    clouds, seeds = [], []
    for i in picks:
        f = frames[int(i)]
        pts = frame_points(f, T=np.eye(4), depth_min=st.depth_min, depth_max=st.depth_max,
                           edge_threshold=st.edge_threshold).xyz
        clouds.append(pts[:: max(1, len(pts) // 60000)])
        z = centre_depth(f, st)
        if z is not None:
            seeds.append([0.0, 0.0, z])
    if not seeds:
        raise ImportError_("no depth at the image centre of any frame: the object must be where the camera looks",
                           code="no_object")
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.concatenate(clouds).astype(np.float64)))
    pts = np.asarray(pcd.voxel_down_sample(cfg.voxel).points)
    seed = np.median(np.asarray(seeds), axis=0)
    up = np.asarray(cfg.camera_up, dtype=np.float64)
    try:
        fit = segment_table(pts, viewpoint=np.zeros(3), distance=st.plane_distance, iterations=st.plane_iterations,
                            seed=st.seed, voxel=st.plane_voxel, min_fraction=st.min_table_fraction,
                            min_points=st.min_table_points, expected_up=up, max_tilt_deg=cfg.max_tilt_deg,
                            seed_point=seed, max_seed_height=st.max_object_height, max_planes=st.table_planes)
    except NoTableError as exc:
        raise ImportError_(f"no table in view: {exc.message}", code="no_table", detail=exc.detail) from None
    n, d = fit.plane.normal, fit.plane.offset  # n . p + d = 0 in the camera frame, n toward the camera
    origin = seed - (seed @ n + d) * n  # the object's foot on the table
    fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n
    if np.linalg.norm(fwd) < 1e-6:  # looking straight down: x along the image's up
        fwd = -np.array([0.0, 1.0, 0.0]) - (-n[1]) * n
    x = fwd / np.linalg.norm(fwd)
    y = np.cross(n, x)
    T_camera_base = make_transform(np.column_stack([x, y, n]), origin)
    height = float(d)  # the camera (origin of its frame) above the plane: n . 0 + d
    look_down = float(np.degrees(np.arcsin(np.clip(-n[2], -1.0, 1.0))))
    return BaseFrame(T_base_camera=invert(T_camera_base), table_normal_cam=n, table_offset_cam=float(d),
                     camera_height_m=height, look_down_deg=look_down, table_fraction=fit.fraction)

"""Object isolation on the real RGB-D frames in shared/data/rgbd (no arm pose: camera = base).

The camera's pose is unknown, so the frame is used with an identity pose and no expected up direction:
the table is found from the data and its normal turned toward the camera.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from common.messages import Intrinsics, RGBDFrame
from services.registration.static import StaticConfig, register_view

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rgbd"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"real RGB-D frames not found at {DATA}")

REAL = StaticConfig(expected_up=None, depth_max=2.0)  # camera pose unknown; scenes reach ~2 m


def graspnet_frame() -> tuple[RGBDFrame, np.ndarray]:
    """The GraspNet RealSense frame and its ground-truth object positions (camera frame, m)."""
    import scipy.io

    d = DATA / "graspnet_realsense"
    meta = scipy.io.loadmat(d / "meta.mat")
    K = meta["intrinsic_matrix"]
    color = np.asarray(Image.open(d / "color.png").convert("RGB"))
    depth = np.asarray(Image.open(d / "depth.png")).astype(np.uint16)
    intr = Intrinsics(
        width=color.shape[1],
        height=color.shape[0],
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
    )
    frame = RGBDFrame(
        color=color,
        depth=depth,
        depth_scale=1.0 / float(meta["factor_depth"].squeeze()),
        intrinsics=intr,
        T_base_camera=np.eye(4),
    )
    return frame, np.asarray(meta["poses"])[:, 3, :].T  # (9, 3) object origins


def uoc_frame(i: int) -> RGBDFrame:
    d = DATA / "tabletop_uoc"
    p = json.loads((d / "camera_params.json").read_text())
    color = np.asarray(Image.open(d / f"{i:06d}-color.png").convert("RGB"))
    depth = np.asarray(Image.open(d / f"{i:06d}-depth.png")).astype(np.uint16)
    intr = Intrinsics(
        width=color.shape[1], height=color.shape[0], fx=p["fx"], fy=p["fy"], cx=p["x_offset"], cy=p["y_offset"]
    )
    return RGBDFrame(color=color, depth=depth, depth_scale=0.001, intrinsics=intr, T_base_camera=np.eye(4))


def check_isolated(frame: RGBDFrame):
    result = register_view([frame], REAL)
    obj = result.object_cloud.xyz.astype(np.float64)
    height = result.table.signed_distance(obj)
    # table gone: nothing on or under the table plane, and the normal faces the camera (at the origin)
    assert height.min() >= REAL.table_clearance
    assert result.table.offset > 0  # origin (camera) on the positive side: n . 0 + d > 0
    # the object stands on the table (its lowest point is near it) and has an object's size
    assert height.min() <= REAL.table_clearance + REAL.max_support_gap
    diag = float(np.linalg.norm(obj.max(axis=0) - obj.min(axis=0)))
    assert 0.03 <= diag <= 0.7, diag
    assert len(obj) >= 100
    # one cluster: the object cloud is connected at the clustering distance
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(obj)).voxel_down_sample(REAL.cluster_voxel)
    labels = np.asarray(pcd.cluster_dbscan(eps=REAL.dbscan_eps * 1.5, min_points=1))
    assert labels.max() == 0
    return result, obj


@pytest.mark.parametrize("i", range(9))
def test_tabletop_frames_isolate_one_object(i):
    check_isolated(uoc_frame(i))


def test_graspnet_frame_isolates_a_known_object():
    frame, gt_positions = graspnet_frame()
    result, obj = check_isolated(frame)
    from scipy.spatial import cKDTree

    # at least one ground-truth object origin lies inside (within 3 cm of) the isolated cloud
    d = cKDTree(obj).query(gt_positions)[0]
    assert d.min() < 0.03, d
    # and the table the data gives is the one the GT objects stand on: their origins are above it
    assert np.all(result.table.signed_distance(gt_positions) > -0.01)

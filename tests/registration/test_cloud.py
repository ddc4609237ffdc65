"""Point-cloud utilities: back-projection against analytic geometry, PLY round trips, conversions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from common.geometry import make_transform, rotation_about_axis, transform_points
from common.messages import Intrinsics, PointCloud, RGBDFrame
from services.registration.cloud import (
    CloudError,
    chromaticity,
    depth_edge_mask,
    downsample,
    frame_points,
    frame_to_cloud,
    from_o3d,
    read_ply,
    to_o3d,
    transform_cloud,
    write_ply,
)

K = Intrinsics(width=64, height=48, fx=50.0, fy=52.0, cx=31.5, cy=23.0)


def plane_frame(z: float = 0.5, T: np.ndarray | None = None) -> RGBDFrame:
    """A fronto-parallel wall at depth ``z``: every pixel back-projects to a known point."""
    depth = np.full((K.height, K.width), int(round(z / 0.001)), dtype=np.uint16)
    color = np.zeros((K.height, K.width, 3), dtype=np.uint8)
    color[..., 0] = np.arange(K.width, dtype=np.uint8)[None, :]
    color[..., 1] = np.arange(K.height, dtype=np.uint8)[:, None]
    return RGBDFrame(
        color=color, depth=depth, depth_scale=0.001, intrinsics=K, T_base_camera=np.eye(4) if T is None else T
    )


def test_back_projection_matches_the_pinhole_model():
    f = plane_frame(0.5)
    pts = frame_points(f)
    assert len(pts) == K.width * K.height
    v, u = np.divmod(pts.pixel, K.width)
    np.testing.assert_allclose(pts.xyz[:, 2], 0.5)
    np.testing.assert_allclose(pts.xyz[:, 0], (u - K.cx) * 0.5 / K.fx)
    np.testing.assert_allclose(pts.xyz[:, 1], (v - K.cy) * 0.5 / K.fy)
    np.testing.assert_array_equal(pts.rgb[:, 0], u)  # colors travel with their pixel
    np.testing.assert_array_equal(pts.rgb[:, 1], v)


def test_points_in_base_use_the_camera_pose_and_range_limits():
    T = make_transform(rotation_about_axis([0, 1, 0], 0.3), [0.1, -0.2, 0.4])
    f = plane_frame(0.5, T)
    f.depth[:10] = 0  # no return
    f.depth[10:12] = 3000  # beyond depth_max
    cam = frame_points(f, depth_max=1.5)
    base = frame_points(f, depth_max=1.5, T=f.T_base_camera)
    assert len(cam) == K.width * (K.height - 12)
    np.testing.assert_allclose(base.xyz, transform_points(T, cam.xyz), atol=1e-12)
    cloud = frame_to_cloud(f, depth_max=1.5)
    assert cloud.frame == "base" and cloud.xyz.dtype == np.float32 and len(cloud) == len(cam)


def test_depth_edges_are_dropped():
    f = plane_frame(0.5)
    f.depth[:, 32:] = 700  # a 20 cm step in the middle
    edge = depth_edge_mask(f.depth * 0.001, 0.01)
    assert edge[:, 31].all() and edge[:, 32].all() and edge.sum() == 2 * K.height
    pts = frame_points(f, edge_threshold=0.01)
    assert len(pts) == K.width * K.height - 2 * K.height


@pytest.mark.parametrize("bad", ["nan_pose", "shape", "scale"])
def test_bad_frames_raise_cloud_error(bad):
    f = plane_frame()
    if bad == "nan_pose":
        f.T_base_camera = np.full((4, 4), np.nan)
    elif bad == "shape":
        f.color = f.color[:-1]
    else:
        f.depth_scale = 0.0
    with pytest.raises(CloudError):
        frame_points(f)


def test_ply_round_trip_keeps_xyz_rgb_normals(tmp_path: Path):
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (500, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, (500, 3), dtype=np.uint8)
    nrm = rng.normal(size=(500, 3))
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32)
    path = write_ply(tmp_path / "sub" / "c.ply", PointCloud(xyz=xyz, rgb=rgb, normals=nrm))
    back = read_ply(path)
    np.testing.assert_allclose(back.xyz, xyz, atol=1e-6)
    np.testing.assert_array_equal(back.rgb, rgb)
    np.testing.assert_allclose(back.normals, nrm, atol=1e-6)
    assert not list(path.parent.glob(".*tmp*"))  # the temporary file was renamed away


def test_conversions_and_transform():
    xyz = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    pc = PointCloud(xyz=xyz, rgb=np.full((3, 3), 255, np.uint8), normals=np.tile([0, 0, 1], (3, 1)).astype(np.float32))
    back = from_o3d(to_o3d(pc))
    np.testing.assert_allclose(back.xyz, xyz)
    np.testing.assert_array_equal(back.rgb, pc.rgb)
    T = make_transform(rotation_about_axis([1, 0, 0], np.pi / 2), [0, 0, 1])
    moved = transform_cloud(pc, T)
    np.testing.assert_allclose(moved.xyz[1], [1, 0, 1], atol=1e-6)
    np.testing.assert_allclose(moved.normals[0], [0, -1, 0], atol=1e-6)
    with pytest.raises(CloudError):
        to_o3d(np.array([[np.nan, 0, 0]]))
    with pytest.raises(CloudError):
        to_o3d(np.zeros((3, 2)))
    with pytest.raises(CloudError):
        to_o3d(np.zeros((3, 3)), rgb=np.zeros((2, 3)))
    with pytest.raises(CloudError):
        read_ply(Path("/nonexistent/x.ply"))


def test_downsample_estimates_normals_toward_the_viewpoint():
    g = np.stack(np.meshgrid(np.linspace(0, 0.2, 60), np.linspace(0, 0.2, 60)), -1).reshape(-1, 2)
    pts = np.column_stack([g, np.zeros(len(g))])
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    for eye, sign in (([0.1, 0.1, 1.0], 1.0), ([0.1, 0.1, -1.0], -1.0)):
        out = downsample(pcd, 0.01, toward=np.array(eye))
        assert 300 < len(out.points) < len(pts)
        np.testing.assert_allclose(np.asarray(out.normals)[:, 2], sign, atol=1e-6)
    with pytest.raises(CloudError):
        downsample(pcd, 0.0)


def test_chromaticity_ignores_brightness_and_keeps_near_black_neutral():
    c = chromaticity(np.array([[200, 100, 50], [100, 50, 25], [0, 0, 2], [2, 0, 0], [0, 0, 0]], np.uint8))
    np.testing.assert_allclose(c.sum(axis=1), 1.0)
    assert np.abs(c[0] - c[1]).sum() < 0.01  # the same colour in shadow (half as bright)
    assert np.abs(c[2] - c[3]).sum() == pytest.approx(0.8)  # two nearly black pixels: not opposite colours
    np.testing.assert_allclose(c[4], 1.0 / 3.0)  # black is grey
    # an averaged Open3D colour (0..1, times 255) reads as the same 8-bit colour
    np.testing.assert_allclose(chromaticity(255.0 * np.array([[200, 100, 50]]) / 255.0), c[:1])

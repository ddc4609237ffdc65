"""The shared registration blocks (FPFH + RANSAC, colour ICP, the paper's overlap removal) on synthetic
geometry with known answers, and the one rigid-transform check every service uses."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from common.errors import ObjscanError
from common.geometry import as_rigid_transform, make_transform, rotation_about_axis, transform_error
from services.registration.blocks import (
    ColorICPConfig,
    FeatureMatchConfig,
    colored_icp,
    fpfh_features,
    mean_spacing,
    overlap_only,
    ransac_feature_match,
)


def _grid(step: float, x0: float = 0.0, size: float = 0.1) -> o3d.geometry.PointCloud:
    g = np.stack(np.meshgrid(np.arange(x0, x0 + size, step), np.arange(0, size, step)), -1).reshape(-1, 2)
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([g, np.zeros(len(g))])))


def _box_cloud(seed: int = 0) -> o3d.geometry.PointCloud:
    """A coloured, textured box surface (6 x 4 x 10 cm) with normals: enough structure for FPFH and colour."""
    rng = np.random.default_rng(seed)
    size = np.array([0.06, 0.04, 0.10])
    pts = rng.uniform(0.0, 1.0, (6000, 3)) * size
    face = rng.integers(0, 6, len(pts))  # push each point onto one of the 6 faces
    pts[np.arange(len(pts)), face % 3] = np.where(face < 3, 0.0, size[face % 3])
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    colors = np.column_stack([0.5 + 0.5 * np.sin(60 * pts[:, 0]), 0.5 + 0.5 * np.cos(45 * pts[:, 2]),
                              0.5 + 0.4 * np.sin(30 * pts[:, 1] + 20 * pts[:, 2])])
    pcd.colors = o3d.utility.Vector3dVector(np.clip(colors + rng.normal(0, 0.01, colors.shape), 0, 1))
    pcd = pcd.voxel_down_sample(0.004)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.01, max_nn=30))
    return pcd


# ------------------------------------------------------------------------------ overlap removal

def test_overlap_only_keeps_points_within_the_mean_spacing():
    a = _grid(0.002)
    b = o3d.geometry.PointCloud(a)
    b.translate([0.05, 0.0, 0.0])  # half of b overlaps a
    assert mean_spacing(a) == pytest.approx(0.002, rel=1e-6)
    sa, sb = overlap_only(a, b, np.eye(4))
    xa = np.asarray(sa.points)[:, 0]
    xb = np.asarray(sb.points)[:, 0]
    assert xa.min() >= 0.05 - 1e-9 and len(sa.points) == pytest.approx(len(a.points) / 2, rel=0.05)
    assert xb.max() <= 0.1 + 1e-9 and len(sb.points) == pytest.approx(len(b.points) / 2, rel=0.05)


def test_overlap_radius_is_each_clouds_own_spacing_as_the_paper_defines_d():
    """A dense source (1 mm) against a sparse target (4 mm) shifted by 2.5 mm across: every target point
    has a source point within its own d (4 mm), but most source points have no target point within their
    d (1 mm). The old dynamic copy used the target's spacing for both sides and kept every source point."""
    src = _grid(0.001, size=0.04)
    tgt = _grid(0.004, size=0.04)
    tgt.translate([0.0, 0.0, 0.0025])
    so, to = overlap_only(src, tgt, np.eye(4))
    assert len(to.points) == len(tgt.points)
    assert len(so.points) == 0  # nearest target point is >= 2.5 mm away: none within 1 mm
    so3, _ = overlap_only(src, tgt, np.eye(4), multiplier=3.0)  # 3 mm: the source points over target points
    assert 0 < len(so3.points) < len(src.points)


def test_overlap_applies_the_transform_to_the_source():
    a = _grid(0.002)
    b = o3d.geometry.PointCloud(a)
    b.translate([0.2, 0.0, 0.0])  # no overlap as they lie...
    assert len(overlap_only(a, b, np.eye(4))[0].points) == 0
    sa, sb = overlap_only(a, b, make_transform(translation=[0.2, 0.0, 0.0]))  # ...but T moves a onto b
    assert len(sa.points) == len(a.points) and len(sb.points) == len(b.points)


def test_overlap_multiplier_must_be_positive():
    a = _grid(0.002)
    with pytest.raises(ValueError, match="multiplier"):
        overlap_only(a, a, np.eye(4), multiplier=0.0)


# ------------------------------------------------------------------------------ FPFH + RANSAC

def test_ransac_feature_match_recovers_a_known_motion_and_is_seeded():
    target = _box_cloud()
    T_true = make_transform(rotation_about_axis([0.2, 1.0, 0.3], 0.7), [0.03, -0.02, 0.05])
    source = o3d.geometry.PointCloud(target).transform(np.linalg.inv(T_true))  # target = T_true @ source
    voxel = 0.004
    fs, ft = fpfh_features(source, voxel), fpfh_features(target, voxel)
    assert fs.data.shape == (33, len(source.points))
    r1 = ransac_feature_match(source, target, fs, ft, 1.5 * voxel, seed=3)
    dt, dr = transform_error(np.asarray(r1.transformation), T_true)
    assert dt < 0.004 and dr < 2.0 and r1.fitness > 0.9
    r2 = ransac_feature_match(source, target, fs, ft, 1.5 * voxel, seed=3)
    np.testing.assert_allclose(np.asarray(r2.transformation), np.asarray(r1.transformation), atol=1e-9)


@pytest.mark.parametrize("bad", [dict(fpfh_radius_factor=0.0), dict(fpfh_max_nn=0), dict(max_iteration=0),
                                 dict(confidence=1.5), dict(edge_length_similarity=0.0), dict(ransac_n=2)])
def test_feature_match_config_rejects_nonsense(bad):
    with pytest.raises(ValueError):
        FeatureMatchConfig(**bad)


# ------------------------------------------------------------------------------ colour ICP

def test_colored_icp_refines_a_small_offset():
    target = _box_cloud()
    T_true = make_transform(rotation_about_axis([0, 0, 1], np.radians(3.0)), [0.003, -0.002, 0.001])
    source = o3d.geometry.PointCloud(target).transform(np.linalg.inv(T_true))
    out = colored_icp(source, target, 0.01, np.eye(4), ColorICPConfig(max_iteration=50))
    assert out.ok and out.fitness > 0.9
    dt, dr = transform_error(out.T, T_true)
    assert dt < 5e-4 and dr < 0.3


def test_colored_icp_failure_keeps_the_initial_transform():
    """No correspondence within max_corr: the run fails, and the caller gets its own init back."""
    target = _box_cloud()
    source = o3d.geometry.PointCloud(target).translate([1.0, 0.0, 0.0])
    init = make_transform(translation=[0.0, 0.0, 0.001])
    out = colored_icp(source, target, 0.005, init)
    assert not out.ok and out.fitness == 0.0 and out.rmse == float("inf")
    np.testing.assert_array_equal(out.T, init)


def test_color_icp_config_rejects_nonsense():
    with pytest.raises(ValueError):
        ColorICPConfig(max_iteration=0)
    with pytest.raises(ValueError):
        ColorICPConfig(lambda_geometric=1.5)


# ------------------------------------------------------------------------------ the rigid-transform check

class _Bad(ObjscanError):
    code = "bad_thing"


def test_rigid_check_accepts_a_pose_and_returns_float64():
    T = make_transform(rotation_about_axis([1, 2, 3], 0.4), [0.1, 0.2, 0.3])
    out = as_rigid_transform(T.tolist(), "T", _Bad)
    assert out.dtype == np.float64 and np.array_equal(out, T)


@pytest.mark.parametrize("bad, code", [
    ("pose", "bad_value"),
    (np.eye(3), "bad_shape"),
    (np.full((4, 4), np.nan), "bad_value"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "bad_value"),  # a reflection
    (np.diag([1.001, 1.0, 1.0, 1.0]), "bad_value"),  # scaled
    (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], dtype=float), "bad_value"),
])
def test_rigid_check_names_what_is_wrong_with_a_typed_error(bad, code):
    with pytest.raises(_Bad) as err:
        as_rigid_transform(bad, "T_a_b", _Bad)
    assert err.value.code == code and err.value.detail["field"] == "T_a_b"
    with pytest.raises(_Bad) as err:
        as_rigid_transform(bad, "T_a_b", _Bad, class_code=True)
    assert err.value.code == "bad_thing"

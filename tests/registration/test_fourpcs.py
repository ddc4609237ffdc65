"""4PCS global registration: recovers known rigid transforms between partial scans (Super4PCS hippo data)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from common.geometry import invert, make_transform, transform_error, transform_points
from services.registration.dynamic.fourpcs import (
    _kabsch_batch,
    _select_base,
    default_max_bases,
    register_4pcs,
    register_4pcs_overlaps,
    score_alignment,
)
from services.registration.dynamic.fourpcs_common import PointCloudInputError
from services.registration.dynamic.global_registration import preprocess, refine_icp

HIPPO = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "clouds" / "super4pcs_hippo"
SCALE = 0.2  # the hippo is ~1 unit long; at 0.2 it is a 20 cm object like the ones we scan
VOXEL = 0.008
needs_hippo = pytest.mark.skipif(not (HIPPO / "hippo1.ply").is_file(),
                                 reason="shared/data/clouds/super4pcs_hippo is absent")


def _load(name: str) -> tuple[np.ndarray, np.ndarray]:
    pcd = o3d.io.read_point_cloud(str(HIPPO / name))
    return np.asarray(pcd.points) * SCALE, np.asarray(pcd.normals)


def _down(xyz: np.ndarray, normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    pcd = preprocess(xyz, VOXEL, normals=normals)
    return np.asarray(pcd.points), np.asarray(pcd.normals)


def _partial_view(xyz: np.ndarray, azimuth_deg: float, elevation_deg: float = 20.0) -> np.ndarray:
    """Points of ``xyz`` visible from a camera 0.6 m away (hidden point removal): a partial scan."""
    c = xyz.mean(axis=0)
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    cam = c + 0.6 * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    _, idx = pcd.hidden_point_removal(cam, 100.0 * 0.6)
    return xyz[np.asarray(idx)]


def _errors(T_est: np.ndarray, T_true: np.ndarray, pts: np.ndarray) -> tuple[float, float]:
    """(RMS displacement of ``pts`` in m, rotation error in deg): errors where the object is, not at the origin."""
    diff = transform_points(T_est, pts) - transform_points(T_true, pts)
    return float(np.sqrt(np.mean(np.sum(diff**2, axis=1)))), transform_error(T_est, T_true)[1]


T_KNOWN = make_transform(Rotation.from_rotvec(np.radians(130.0) * np.array([0.48, -0.6, 0.64])
                                              / np.linalg.norm([0.48, -0.6, 0.64])).as_matrix(),
                         [0.12, -0.05, 0.3])


@needs_hippo
def test_recovers_known_transform_between_two_partial_views():
    """Two hidden-point-removal views of the hippo 50 degrees apart; the source is moved by a known T."""
    full, _ = _load("hippo1.ply")
    view_a, view_b = _partial_view(full, 0.0), _partial_view(full, 50.0)
    src_xyz, src_n = _down(transform_points(T_KNOWN, view_b))
    tgt_xyz, tgt_n = _down(view_a)
    res = register_4pcs(src_xyz, tgt_xyz, overlap=0.7, delta=VOXEL, seed=0, max_time_s=20.0,
                        source_normals=src_n, target_normals=tgt_n)
    T_true = invert(T_KNOWN)
    t_err, r_err = _errors(res.T, T_true, src_xyz)
    assert r_err < 5.0 and t_err < VOXEL, (t_err, r_err)  # raw 4PCS: within delta, a few degrees
    assert res.lcp_score > 0.5 and res.n_bases_tried >= 1
    T_fine, fitness, _ = refine_icp(transform_points(T_KNOWN, view_b), view_a, res.T, voxel=0.002)
    t_err, r_err = _errors(T_fine, T_true, src_xyz)
    assert r_err < 0.3 and t_err < 0.0005, (t_err, r_err)  # after ICP: sub-mm, tenths of a degree
    assert fitness > 0.5


@needs_hippo
def test_real_hippo_pair_is_consistent_under_a_known_transform():
    """The two real Super4PCS scans: moving the source by T_KNOWN must change the answer by exactly T_KNOWN."""
    a, an = _load("hippo1.ply")
    b, bn = _load("hippo2.ply")
    ta, tan = _down(a, an)
    sb, sbn = _down(b, bn)
    ref = register_4pcs(sb, ta, overlap=0.85, delta=VOXEL, seed=1, source_normals=sbn, target_normals=tan)
    T_ref, fit_ref, rmse_ref = refine_icp(b, a, ref.T, voxel=0.002)
    assert fit_ref > 0.7 and rmse_ref < 0.002  # the reference alignment itself is a good one
    moved, moved_n = _down(transform_points(T_KNOWN, b), bn @ T_KNOWN[:3, :3].T)
    res = register_4pcs(moved, ta, overlap=0.85, delta=VOXEL, seed=7, source_normals=moved_n,
                        target_normals=tan)
    expected = T_ref @ invert(T_KNOWN)
    t_err, r_err = _errors(res.T, expected, moved)
    assert r_err < 5.0 and t_err < VOXEL, (t_err, r_err)
    T_fine, _, _ = refine_icp(transform_points(T_KNOWN, b), a, res.T, voxel=0.002)
    t_err, r_err = _errors(T_fine, expected, moved)
    assert r_err < 0.3 and t_err < 0.0005, (t_err, r_err)


@needs_hippo
def test_without_normals_still_registers():
    full, _ = _load("hippo1.ply")
    src = _down(transform_points(T_KNOWN, _partial_view(full, 40.0)))[0]
    tgt = _down(_partial_view(full, 0.0))[0]
    res = register_4pcs(src, tgt, overlap=0.7, delta=VOXEL, seed=3, max_time_s=30.0)
    t_err, r_err = _errors(res.T, invert(T_KNOWN), src)
    assert r_err < 5.0 and t_err < VOXEL, (t_err, r_err)
    assert res.extra["used_normals"] is False


def test_same_seed_same_answer_and_budget_respected():
    rng = np.random.default_rng(0)
    target = rng.normal(size=(400, 3)) * [0.05, 0.03, 0.02]
    T = make_transform(Rotation.from_euler("xyz", [40, -20, 75], degrees=True).as_matrix(), [0.1, 0, 0.02])
    source = transform_points(invert(T), target)
    r1 = register_4pcs(source, target, overlap=0.95, delta=0.004, seed=5, max_time_s=5.0, max_bases=6)
    r2 = register_4pcs(source, target, overlap=0.95, delta=0.004, seed=5, max_time_s=5.0, max_bases=6)
    np.testing.assert_array_equal(r1.T, r2.T)
    assert r1.n_bases_tried <= 6
    t_err, r_err = transform_error(r1.T, T)  # full overlap, exact copy: recovered to within delta
    assert r_err < 2.0 and t_err < 0.004


def test_kabsch_batch_recovers_exact_rigid_motions():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(4, 3))
    Rs = Rotation.random(5, random_state=2).as_matrix()
    ts = rng.normal(size=(5, 3))
    Qs = np.einsum("mij,kj->mki", Rs, B) + ts[:, None, :]
    R, t, rms = _kabsch_batch(B, Qs)
    np.testing.assert_allclose(R, Rs, atol=1e-9)
    np.testing.assert_allclose(t, ts, atol=1e-9)
    assert np.all(rms < 1e-9)
    _, _, rms_bad = _kabsch_batch(B, Qs[:, ::-1, :])  # permuted correspondences do not fit
    assert np.all(rms_bad > 0.1)


def test_base_is_wide_coplanar_and_its_segments_cross():
    rng = np.random.default_rng(3)
    S = rng.normal(size=(1500, 3))
    S = 0.1 * S / np.linalg.norm(S, axis=1, keepdims=True)  # a sphere surface, like a scanned object
    bases = [b for b in (_select_base(S, rng, max_base=0.15, coplanar_tol=0.004, trials=64)
                         for _ in range(20)) if b is not None]
    assert len(bases) >= 15  # a base is found almost every time on a surface
    for quad, r1, r2 in bases:
        B = S[quad]
        assert len(set(quad.tolist())) == 4
        assert max(np.linalg.norm(B[i] - B[j]) for i in range(4) for j in range(i)) > 0.05  # wide
        n = np.cross(B[1] - B[0], B[2] - B[0])
        assert abs((B[3] - B[0]) @ n / np.linalg.norm(n)) <= 0.004
        assert 0.1 <= r1 <= 0.9 and 0.1 <= r2 <= 0.9
        e1, e2 = B[0] + r1 * (B[1] - B[0]), B[2] + r2 * (B[3] - B[2])
        assert np.linalg.norm(e1 - e2) <= 0.004  # the two segments (nearly) intersect


def test_lcp_score_counts_points_within_delta():
    rng = np.random.default_rng(4)
    P = rng.uniform(size=(500, 3))
    assert score_alignment(P, P, np.eye(4), 0.001) == (1.0, 1.0)
    assert score_alignment(P, P, make_transform(translation=[5.0, 0, 0]), 0.01) == (0.0, 0.0)


def test_default_bases_grow_as_overlap_shrinks():
    assert default_max_bases(0.9) < default_max_bases(0.8) < default_max_bases(0.5)


@pytest.mark.parametrize("bad", [np.zeros((3, 3)), np.zeros((10, 2)), np.full((10, 3), np.nan)])
def test_bad_clouds_raise_typed_errors(bad):
    good = np.random.default_rng(0).normal(size=(50, 3))
    with pytest.raises(PointCloudInputError):
        register_4pcs(bad, good)
    with pytest.raises(PointCloudInputError):
        register_4pcs(good, bad)


def test_bad_parameters_raise_typed_errors():
    P = np.random.default_rng(0).normal(size=(50, 3))
    with pytest.raises(PointCloudInputError):
        register_4pcs(P, P, overlap=1.5)
    with pytest.raises(PointCloudInputError):
        register_4pcs(P, P, delta=0.0)
    with pytest.raises(PointCloudInputError):
        register_4pcs(P, P, source_normals=np.ones((10, 3)), target_normals=np.ones((50, 3)))
    with pytest.raises(PointCloudInputError):
        register_4pcs_overlaps(P, P, overlaps=[])
    with pytest.raises(PointCloudInputError):
        register_4pcs_overlaps(P, P, overlaps=[0.9, 0.0])


def test_overlaps_share_one_setup_and_report_each_run():
    rng = np.random.default_rng(6)
    target = np.vstack([rng.uniform([0, 0, 0], [0.12, 0.03, 0.02], size=(600, 3)),
                        rng.uniform([0, 0.03, 0], [0.03, 0.08, 0.05], size=(300, 3))])
    T = make_transform(Rotation.from_euler("xyz", [10, 70, -30], degrees=True).as_matrix(), [0.0, 0.1, 0.0])
    runs = register_4pcs_overlaps(transform_points(invert(T), target), target, overlaps=(0.9, 0.85, 0.8),
                                  delta=0.006, seed=2)
    assert [r.overlap for r in runs] == [0.9, 0.85, 0.8]
    best = max(runs, key=lambda r: r.score)
    rms, rot = _errors(best.T, T, transform_points(invert(T), target))
    assert rot < 3.0 and rms < 0.006


def test_degenerate_clouds_return_identity_without_crashing():
    """A straight line has no coplanar base: no pose is claimed (identity, LCP 0), nothing raises."""
    line = np.column_stack([np.linspace(0, 0.1, 50), np.zeros(50), np.zeros(50)])
    res = register_4pcs(line, line, max_bases=10)
    np.testing.assert_array_equal(res.T, np.eye(4))
    assert res.lcp_score == 0.0 and res.n_bases_tried == 10

"""global_register: one interface over 4PCS, FPFH-RANSAC and FGR with comparable scores."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from common.geometry import invert, make_transform, transform_points
from services.registration.dynamic.fourpcs_common import PointCloudInputError
from services.registration.dynamic.global_registration import (
    PAPER_OVERLAPS,
    GlobalRegistrationConfig,
    global_register,
    preprocess,
    refine_icp,
    score_alignment,
)
from tests.registration.test_fourpcs import T_KNOWN, _errors, _load, _partial_view, needs_hippo


@pytest.fixture(scope="module")
def hippo_views() -> tuple[np.ndarray, np.ndarray]:
    """(source, target): two partial views 50 degrees apart; the source moved by T_KNOWN (truth: T_KNOWN^-1)."""
    full, _ = _load("hippo1.ply")
    return transform_points(T_KNOWN, _partial_view(full, 50.0)), _partial_view(full, 0.0)


@needs_hippo
@pytest.mark.parametrize("method", ["4pcs", "fpfh_ransac"])
def test_methods_recover_the_known_transform_after_icp(hippo_views, method):
    src, tgt = hippo_views
    res = global_register(src, tgt, method, voxel=0.008, seed=0)
    assert res.method == method and res.seconds > 0
    T_fine, _, _ = refine_icp(src, tgt, res.T, voxel=0.002)
    rms, rot = _errors(T_fine, invert(T_KNOWN), src)
    assert rot < 0.3 and rms < 0.0005, (rms, rot)


@needs_hippo
def test_4pcs_runs_the_paper_overlaps_and_keeps_the_best(hippo_views):
    src, tgt = hippo_views
    paper = GlobalRegistrationConfig(fourpcs_skip_after_confirmed=False)
    res = global_register(src, tgt, "4pcs", voxel=0.008, seed=0, config=paper)
    per_overlap = res.extra["scores_per_overlap"]
    assert sorted(per_overlap) == sorted(PAPER_OVERLAPS)
    assert res.overlap in PAPER_OVERLAPS
    # the returned score is recomputed on the whole down-sampled clouds: close to the winner's sample score
    assert res.score == pytest.approx(max(per_overlap.values()), abs=0.05)
    rms, rot = _errors(res.T, invert(T_KNOWN), src)
    assert rot < 5.0 and rms < 0.008  # raw: within delta
    fast = global_register(src, tgt, "4pcs", voxel=0.008, seed=0)  # default: stop once a pose is confirmed
    ran = list(fast.extra["scores_per_overlap"])
    assert ran == list(PAPER_OVERLAPS[: len(ran)]) and fast.n_bases_tried <= res.n_bases_tried
    rms, rot = _errors(fast.T, invert(T_KNOWN), src)
    assert rot < 5.0 and rms < 0.008


@needs_hippo
def test_scores_are_the_same_measure_for_every_method(hippo_views):
    src, tgt = hippo_views
    s_down = np.asarray(preprocess(src, 0.008).points)
    t_down = np.asarray(preprocess(tgt, 0.008).points)
    for method in ("4pcs", "fpfh_ransac", "fgr"):
        res = global_register(src, tgt, method, voxel=0.008, seed=1, overlap=0.8)
        R = res.T[:3, :3]
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)  # a proper rigid transform
        assert np.linalg.det(R) == pytest.approx(1.0)
        lcp, weighted = score_alignment(s_down, t_down, res.T, 0.008)
        assert res.lcp_score == pytest.approx(lcp) and res.score == pytest.approx(weighted)
        assert 0.0 <= res.score <= res.lcp_score <= 1.0
    # the truth scores high; a transform 5 cm off scores nothing
    assert score_alignment(s_down, t_down, invert(T_KNOWN), 0.008)[0] > 0.6
    off = invert(T_KNOWN)
    off[:3, 3] += [0.05, 0, 0]
    assert score_alignment(s_down, t_down, off, 0.008)[0] < 0.2


def test_accepts_open3d_clouds_and_given_normals():
    rng = np.random.default_rng(0)  # an L-shaped volume: no symmetry that makes a flip fit as well
    pts = np.vstack([rng.uniform([0, 0, 0], [0.12, 0.03, 0.02], size=(2000, 3)),
                     rng.uniform([0, 0.03, 0], [0.03, 0.08, 0.05], size=(1000, 3))])
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    res = global_register(pcd, pcd, "4pcs", voxel=0.008, overlap=0.95, seed=0)
    rms, rot = _errors(res.T, np.eye(4), pts)
    assert rot < 3.0 and rms < 0.008
    normals = np.tile([0.0, 0.0, 1.0], (3000, 1))
    down = preprocess(pts, 0.008, normals=normals)
    np.testing.assert_allclose(np.abs(np.asarray(down.normals)[:, 2]), 1.0)


def test_bad_arguments_raise_typed_errors():
    pts = np.random.default_rng(1).normal(size=(200, 3)) * 0.05
    with pytest.raises(PointCloudInputError):
        global_register(pts, pts, "icp")
    with pytest.raises(PointCloudInputError):
        global_register(pts, pts, "4pcs", voxel=0.0)
    with pytest.raises(PointCloudInputError):
        global_register(pts, pts, "4pcs", overlap=[])
    with pytest.raises(PointCloudInputError):
        global_register(pts, np.full((10, 3), np.nan))
    with pytest.raises(PointCloudInputError):
        global_register(pts[:2] * 0, pts)  # collapses to fewer than 4 points


def test_prior_is_kept_when_geometry_cannot_tell_and_dropped_when_it_can():
    rng = np.random.default_rng(3)
    # a can: every turn about its axis fits equally well, so the prior (the true turn) must be kept
    ang = rng.uniform(0, 2 * np.pi, 6000)
    can = np.column_stack([0.035 * np.cos(ang), 0.035 * np.sin(ang), rng.uniform(0, 0.1, 6000)])
    turn = make_transform(Rotation.from_euler("z", 25, degrees=True).as_matrix())
    truth = invert(turn)
    res = global_register(transform_points(turn, can), can, "4pcs", voxel=0.008, seed=0, prior_T=truth)
    assert res.extra["kept_prior"] is True
    np.testing.assert_allclose(res.T[:3, :3], truth[:3, :3])  # the prior's rotation is kept as it is
    np.testing.assert_allclose(res.T[:3, 3], truth[:3, 3], atol=0.001)  # translation only touched up
    # an L-shaped block with a prior 40 degrees off: the clearly better global fit wins
    block = np.vstack([rng.uniform([0, 0, 0], [0.12, 0.03, 0.02], size=(2000, 3)),
                       rng.uniform([0, 0.03, 0], [0.03, 0.08, 0.05], size=(1000, 3))])
    bad_prior = make_transform(Rotation.from_euler("z", 40, degrees=True).as_matrix()) @ truth
    res = global_register(transform_points(turn, block), block, "4pcs", voxel=0.008, seed=0, prior_T=bad_prior)
    assert res.extra["kept_prior"] is False
    rms, rot = _errors(res.T, truth, transform_points(turn, block))
    assert rot < 3.0 and rms < 0.008

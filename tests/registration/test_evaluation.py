"""Model evaluation: Chamfer / accuracy / completeness / F-score against analytic ground truth, and alignment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from common.geometry import invert, make_transform, transform_error, transform_points
from services.registration.dynamic.fourpcs_common import PointCloudInputError
from services.registration.evaluation import chamfer_metrics, evaluate_model, point_errors

GOOD_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "clouds" / "good_descriptor"


def _sphere(n: int, radius: float, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def _plane(n_side: int, half: float) -> np.ndarray:
    g = np.linspace(-half, half, n_side)
    xx, yy = np.meshgrid(g, g)
    return np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])


def test_noisy_sphere_accuracy_matches_the_noise():
    """Radial Gaussian noise sigma: the exact mean distance to the sphere is sigma * sqrt(2 / pi)."""
    r, sigma = 0.05, 0.001
    rng = np.random.default_rng(0)
    model = _sphere(20000, 1.0, 1) * (r + rng.normal(0, sigma, (20000, 1)))
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=r, resolution=200)  # facets deviate < 10 um
    out = evaluate_model(model, mesh, align=False)
    expected_mm = 1000 * sigma * np.sqrt(2 / np.pi)
    assert out["accuracy_mm"] == pytest.approx(expected_mm, rel=0.05)
    assert out["chamfer_mm"] == pytest.approx(0.5 * (out["accuracy_mm"] + out["completeness_mm"]))
    # 1 mm noise: |e| < 2 mm for 95.4 % of the points, < 5 mm for all
    assert out["precision_2mm"] == pytest.approx(0.954, abs=0.01)
    assert out["precision_5mm"] == pytest.approx(1.0, abs=1e-3)


def test_shifted_sphere_without_alignment_gives_half_the_shift():
    """Points of a sphere moved by s lie |s cos(theta)| from it: on average s / 2 (exactly, to O(s^2 / r))."""
    r, s = 0.05, 0.002
    gt = _sphere(300000, r, 2)
    model = _sphere(30000, r, 3) + [s, 0, 0]
    out = evaluate_model(model, gt, align=False)
    assert out["accuracy_mm"] == pytest.approx(1000 * s / 2, rel=0.06)
    assert out["aligned"] is False and np.allclose(out["T_gt_model"], np.eye(4))


def test_plane_shifted_along_its_normal_gives_the_shift_and_the_f_scores():
    s = 0.003
    gt = _plane(401, 0.1)  # 0.5 mm grid, wider than the model so every model point sits over a GT point
    model = gt[np.all(np.abs(gt[:, :2]) <= 0.05 + 1e-9, axis=1)] + [0, 0, s]
    errors = point_errors(model, gt)
    np.testing.assert_allclose(errors, s, atol=1e-9)
    out = chamfer_metrics(model, gt)
    assert out["accuracy_mm"] == pytest.approx(3.0, abs=1e-6)
    assert out["precision_2mm"] == 0.0 and out["precision_5mm"] == 1.0
    assert out["fscore_2mm"] == 0.0
    recall = out["recall_5mm"]  # GT points within 5 mm of the model: the central part of the GT plane
    assert 0.2 < recall < 0.35
    assert out["fscore_5mm"] == pytest.approx(2 * recall / (1 + recall))


def test_alignment_recovers_a_known_rigid_motion():
    path = GOOD_DATA / "vase.pcd"
    if not path.is_file():
        pytest.skip("shared/data/clouds/good_descriptor is absent")
    gt = np.asarray(o3d.io.read_point_cloud(str(path)).points, dtype=np.float64)
    gt = (gt - gt.mean(axis=0)) * 2.0  # ~20 cm vase
    T = make_transform(Rotation.from_euler("xyz", [8, -5, 20], degrees=True).as_matrix(), [0.01, -0.02, 0.005])
    model = transform_points(T, gt[::2])
    before = evaluate_model(model, gt, align=False)
    out = evaluate_model(model, gt, align=True)
    t_err, r_err = transform_error(np.array(out["T_gt_model"]), invert(T))
    assert r_err < 0.2 and t_err < 0.0005
    assert out["accuracy_mm"] < 0.05 < 2.0 < before["accuracy_mm"]  # the model is a subset of the GT
    assert out["chamfer_mm"] < before["chamfer_mm"]
    assert out["aligned"] is True


def _hollow_box() -> np.ndarray:
    rng = np.random.default_rng(5)
    pts = rng.uniform([-0.04, -0.02, 0], [0.04, 0.02, 0.15], size=(20000, 3))
    return pts[(np.abs(pts[:, 0]) > 0.035) | (np.abs(pts[:, 1]) > 0.015) | (pts[:, 2] > 0.14)]


def test_alignment_without_a_guess_recovers_a_large_turn():
    """150 degrees is beyond ICP's reach from the identity; the principal-axes candidates bring it in."""
    gt = _hollow_box()
    T = make_transform(Rotation.from_euler("z", 150, degrees=True).as_matrix(), [0.3, 0.1, 0.0])
    out = evaluate_model(transform_points(T, gt), gt, align=True)
    t_err, r_err = transform_error(np.array(out["T_gt_model"]), invert(T))
    assert r_err < 0.5 and t_err < 0.001
    assert out["chamfer_mm"] < 0.1


def test_initial_guess_is_applied_when_not_aligning():
    gt = _hollow_box()
    T = make_transform(Rotation.from_euler("z", 150, degrees=True).as_matrix(), [0.3, 0.1, 0.0])
    model = transform_points(T, gt)
    out = evaluate_model(model, gt, align=False, init_T=invert(T))
    np.testing.assert_allclose(np.array(out["T_gt_model"]), invert(T))
    assert out["chamfer_mm"] < 1e-6
    assert evaluate_model(model, gt, align=False)["chamfer_mm"] > 50.0


def test_identical_clouds_are_perfect_and_all_keys_present():
    gt = _sphere(5000, 0.05, 6)
    out = evaluate_model(gt, gt, align=False)
    for key in ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm", "precision_2mm",
                "precision_5mm", "recall_2mm", "recall_5mm", "T_gt_model"):
        assert key in out
    assert out["chamfer_mm"] == 0.0 and out["fscore_2mm"] == 1.0 and out["fscore_5mm"] == 1.0


@pytest.mark.parametrize("bad", [np.zeros((0, 3)), np.zeros((5, 4)), np.array([[0, 0, np.inf]] * 5)])
def test_bad_inputs_raise_typed_errors(bad):
    good = _sphere(100, 0.05, 7)
    with pytest.raises(PointCloudInputError):
        evaluate_model(bad, good)
    with pytest.raises(PointCloudInputError):
        evaluate_model(good, bad)
    with pytest.raises(PointCloudInputError):
        point_errors(bad, good)


def test_bad_initial_guess_raises():
    good = _sphere(100, 0.05, 8)
    with pytest.raises(PointCloudInputError):
        evaluate_model(good, good, init_T=np.eye(3))

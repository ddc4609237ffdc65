"""GOOD descriptor: invariance, descriptiveness on the reference repository's clouds, ordering rules, regions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from services.registration.dynamic.fourpcs_common import PointCloudInputError
from services.registration.dynamic.good import (
    good_descriptor,
    good_distance,
    segment_regions,
    top_region_pairs,
)

GOOD_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "clouds" / "good_descriptor"
OBJECTS = ("bottle", "bowl", "plate", "vase")
needs_data = pytest.mark.skipif(not (GOOD_DATA / "vase.pcd").is_file(),
                                reason="shared/data/clouds/good_descriptor is absent")


def _cloud(name: str) -> np.ndarray:
    return np.asarray(o3d.io.read_point_cloud(str(GOOD_DATA / f"{name}.pcd")).points, dtype=np.float64)


def _entropy(p: np.ndarray) -> float:
    nz = p[p > 0]
    return float(-np.sum(nz * np.log2(nz)))


def _variance(p: np.ndarray, offset: float) -> float:
    i = np.arange(p.size) + offset
    mu = np.sum(i * p)
    return float(np.sum((i - mu) ** 2 * p))


def _asymmetric_blob(n: int = 3000, seed: int = 0) -> np.ndarray:
    """An L-shaped, uneven cloud: no symmetry that would leave GOOD's axis signs undetermined."""
    rng = np.random.default_rng(seed)
    a = rng.uniform([0, 0, 0], [0.12, 0.03, 0.02], size=(2 * n // 3, 3))
    b = rng.uniform([0, 0.03, 0], [0.03, 0.08, 0.05], size=(n - 2 * n // 3, 3))
    return np.vstack([a, b])


@pytest.mark.parametrize("convention", ["kasaei", "colthurst"])
@pytest.mark.parametrize("n_bins", [5, 10, 30])
def test_length_and_each_projection_normalised(convention, n_bins):
    d = good_descriptor(_asymmetric_blob(), n_bins, convention=convention)
    assert d.shape == (3 * n_bins**2,)
    np.testing.assert_allclose(d.reshape(3, -1).sum(axis=1), 1.0, atol=1e-12)
    assert np.all(d >= 0)


@pytest.mark.parametrize("convention", ["kasaei", "colthurst"])
def test_invariant_to_rotation_and_translation(convention):
    pts = _asymmetric_blob()
    rng = np.random.default_rng(1)
    for n_bins in (5, 15, 50):
        ref = good_descriptor(pts, n_bins, convention=convention)
        for k in range(10):
            R = Rotation.random(random_state=k).as_matrix()
            moved = pts @ R.T + rng.normal(0, 0.5, 3)
            assert good_distance(ref, good_descriptor(moved, n_bins, convention=convention)) < 1e-3


@needs_data
def test_invariant_on_reference_clouds_and_different_shapes_differ():
    """Rotated copies stay put; the four reference objects are far apart compared with that."""
    descs = {name: good_descriptor(_cloud(name), 15) for name in OBJECTS}
    for k, name in enumerate(OBJECTS):
        R = Rotation.random(random_state=10 + k).as_matrix()
        rotated = good_descriptor(_cloud(name) @ R.T + [0.3, -1.0, 2.0], 15)
        assert good_distance(descs[name], rotated) < 1e-3
    between = [good_distance(descs[a], descs[b]) for i, a in enumerate(OBJECTS) for b in OBJECTS[i + 1:]]
    assert min(between) > 0.2


@needs_data
def test_noisy_subsampled_views_are_recognised():
    """Nearest-descriptor recognition of rotated, noisy, half-subsampled copies of the reference objects."""
    rng = np.random.default_rng(2)
    gallery = {name: good_descriptor(_cloud(name), 15) for name in OBJECTS}
    for k, name in enumerate(OBJECTS):
        pts = _cloud(name)
        pts = pts[rng.choice(len(pts), len(pts) // 2, replace=False)]
        pts = pts @ Rotation.random(random_state=20 + k).as_matrix().T + rng.normal(0, 0.001, pts.shape)
        query = good_descriptor(pts, 15)
        best = min(OBJECTS, key=lambda g: good_distance(gallery[g], query))
        assert best == name


def test_kasaei_orders_by_entropy_then_increasing_variance():
    for seed in range(5):
        d = good_descriptor(_asymmetric_blob(seed=seed), 10, convention="kasaei").reshape(3, -1)
        ent = [_entropy(p) for p in d]
        assert ent[0] == pytest.approx(max(ent))
        assert _variance(d[1], 1.0) <= _variance(d[2], 1.0) + 1e-12


def test_colthurst_orders_by_entropy_then_decreasing_variance():
    for seed in range(5):
        d = good_descriptor(_asymmetric_blob(seed=seed), 10, convention="colthurst").reshape(3, -1)
        ent = [_entropy(p) for p in d]
        assert ent[0] == pytest.approx(max(ent))
        assert _variance(d[1], 0.0) >= _variance(d[2], 0.0) - 1e-12


def test_projection_plane_sizes_of_both_conventions():
    """A 9 cm segment at n = 12: Kasaei's plane is 9 + 2 cm wide, so the segment spans bins 1..10 (10 of
    12); Colthurst's is 2 max|coord| = 9 cm, so it spans all 12."""
    x = np.linspace(-0.045, 0.045, 2001)
    line = np.column_stack([x, 1e-4 * np.sin(40 * x), 1e-4 * np.cos(30 * x)])
    for convention, expected in (("kasaei", 10), ("colthurst", 12)):
        d = good_descriptor(line, 12, convention=convention).reshape(3, 12, 12)
        spans = [max(np.count_nonzero(p.sum(axis=0)), np.count_nonzero(p.sum(axis=1))) for p in d]
        assert max(spans) == expected


def test_distance_metrics():
    a = good_descriptor(_asymmetric_blob(seed=0), 10)
    b = good_descriptor(_asymmetric_blob(seed=0)[:, [1, 0, 2]] * [1.0, 2.0, 0.5], 10)
    for metric in ("chi2", "euclidean", "js"):
        assert good_distance(a, a, metric) == pytest.approx(0.0, abs=1e-12)
        assert good_distance(a, b, metric) == pytest.approx(good_distance(b, a, metric))
        assert good_distance(a, b, metric) > 0
    assert good_distance(a, b, "euclidean") == pytest.approx(np.linalg.norm(a - b))
    # disjoint histograms: chi2 and JS reach their maximum of 1 per projection
    p = np.zeros(12)
    q = np.zeros(12)
    p[[0, 4, 8]] = 1.0
    q[[1, 5, 9]] = 1.0
    assert good_distance(p, q, "chi2") == pytest.approx(3.0)
    assert good_distance(p, q, "js") == pytest.approx(3.0)


def test_segment_regions_separates_blobs_and_drops_small_ones():
    rng = np.random.default_rng(3)
    blob_a = rng.normal([0, 0, 0], 0.01, size=(400, 3))
    blob_b = rng.normal([0.1, 0, 0], 0.01, size=(300, 3))
    speck = rng.normal([0.05, 0.1, 0], 0.001, size=(5, 3))
    regions = segment_regions(np.vstack([blob_a, blob_b, speck]), n_regions=3, min_points=30)
    assert [len(r) for r in regions] == [400, 300]
    assert set(regions[0].tolist()) == set(range(400))
    assert set(regions[1].tolist()) == set(range(400, 700))


def test_segment_regions_uses_color_and_normals():
    """A flat patch split only by its print colour: position alone cannot find the boundary."""
    rng = np.random.default_rng(4)
    xy = rng.uniform(-0.05, 0.05, size=(2000, 2))
    pts = np.column_stack([xy, np.zeros(2000)])
    colors = np.where((xy[:, 0] > 0.02)[:, None], [[255, 0, 0]], [[0, 0, 255]])
    normals = np.tile([0.0, 0.0, 1.0], (2000, 1))
    regions = segment_regions(pts, normals, colors, n_regions=2, color_weight=5.0)
    red = set(np.flatnonzero(xy[:, 0] > 0.02).tolist())
    assert any(set(r.tolist()) == red for r in regions)


def test_top_region_pairs_match_the_same_part_in_a_rotated_copy():
    pts = _asymmetric_blob(4000, seed=5)
    R = Rotation.from_euler("z", 35, degrees=True).as_matrix()
    moved = pts @ R.T + [0.2, 0.0, 0.0]
    regions_a = segment_regions(pts, n_regions=5)
    regions_b = segment_regions(moved, n_regions=5)
    pairs = top_region_pairs(regions_a, regions_b, pts, moved, n_values=(10, 30, 50), k=3)
    assert len(pairs) == 3
    assert [p.distance for p in pairs] == sorted(p.distance for p in pairs)
    for p in pairs:
        assert set(regions_a[p.index_a].tolist()) == set(regions_b[p.index_b].tolist())
        assert p.distance < 1e-3 and len(p.distances_per_n) == 3
    assert len({p.index_a for p in pairs}) == 3 and len({p.index_b for p in pairs}) == 3


def test_bad_inputs_raise_typed_errors():
    with pytest.raises(PointCloudInputError):
        good_descriptor(np.zeros((2, 3)))
    with pytest.raises(PointCloudInputError):
        good_descriptor(np.full((10, 3), np.nan))
    with pytest.raises(PointCloudInputError):
        good_descriptor(_asymmetric_blob(), convention="pcl")
    with pytest.raises(PointCloudInputError):
        good_distance(np.zeros(75), np.zeros(12))
    with pytest.raises(PointCloudInputError):
        segment_regions(np.zeros((3, 3)), n_regions=5)
    with pytest.raises(PointCloudInputError):
        segment_regions(_asymmetric_blob(), normals=np.ones((5, 3)))

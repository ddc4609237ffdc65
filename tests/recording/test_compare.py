"""compare_models: the determinism check's figures against clouds whose difference is known."""

from __future__ import annotations

import numpy as np

from common.messages import PointCloud
from services.recording.compare import compare_models


def _cloud(seed: int = 0, n: int = 2000) -> PointCloud:
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-0.05, 0.05, (n, 3)).astype(np.float32)
    normals = rng.normal(size=(n, 3)).astype(np.float32)
    return PointCloud(xyz=xyz, rgb=rng.integers(0, 255, (n, 3), dtype=np.uint8), normals=normals)


def test_identical_clouds_are_identical():
    a = _cloud()
    b = PointCloud(xyz=a.xyz.copy(), rgb=a.rgb.copy(), normals=a.normals.copy())
    out = compare_models(a, b)
    assert out["identical"] and out["within_tolerance"] and out["hausdorff_mm"] == 0.0


def test_a_shift_of_one_millimetre_is_measured():
    a = _cloud()
    b = PointCloud(xyz=a.xyz + np.float32(0.001), rgb=a.rgb, normals=a.normals)
    out = compare_models(a, b, tolerance_mm=0.5)
    assert not out["identical"] and not out["xyz_identical"] and out["rgb_identical"]
    assert out["max_pointwise_diff_mm"] > 0.99 and out["max_pointwise_diff_mm"] < 1.01
    assert out["hausdorff_mm"] <= np.sqrt(3) * 1.0 + 1e-3  # nearest neighbour never farther than the shift
    assert not out["within_tolerance"] or out["hausdorff_mm"] <= 0.5


def test_normals_differing_in_the_last_bit_are_reported_apart():
    a = _cloud()
    b = PointCloud(xyz=a.xyz, rgb=a.rgb, normals=np.nextafter(a.normals, np.float32(np.inf)))
    out = compare_models(a, b)
    assert out["xyz_identical"] and out["rgb_identical"] and not out["normals_identical"]
    assert 0 < out["normals_max_diff"] < 1e-6
    assert out["hausdorff_mm"] == 0.0 and out["within_tolerance"]


def test_an_empty_replay_is_not_within_tolerance():
    a = _cloud()
    empty = PointCloud(xyz=np.zeros((0, 3), np.float32))
    assert compare_models(a, empty)["within_tolerance"] is False

"""``transform_points`` / ``rotate_vectors`` (written column by column for speed) match the matrix product."""

from __future__ import annotations

import numpy as np

from common.geometry import make_transform, rotate_vectors, transform_points


def _pose(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return make_transform(q * np.sign(np.linalg.det(q)), rng.normal(size=3))


def test_same_values_as_the_matrix_product_for_every_shape_and_dtype():
    rng = np.random.default_rng(3)
    T = _pose(rng)
    for pts in (rng.normal(size=(1000, 3)), rng.normal(size=(1000, 3)).astype(np.float32), rng.normal(size=3),
                np.zeros((0, 3))):
        ref = pts.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        out = transform_points(T, pts)
        assert out.shape == pts.shape and out.dtype == pts.dtype
        assert np.allclose(out, ref.astype(pts.dtype), rtol=0, atol=1e-12 if pts.dtype == np.float64 else 1e-6)
        rot = rotate_vectors(T, pts)
        assert rot.dtype == pts.dtype
        assert np.allclose(rot, (pts.astype(np.float64) @ T[:3, :3].T).astype(pts.dtype), rtol=0, atol=1e-6)


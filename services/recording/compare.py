"""The determinism check: is a replayed model the recorded one, bit for bit or within a tolerance?"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from common.messages import PointCloud


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def compare_models(recorded: PointCloud, replayed: PointCloud, tolerance_mm: float = 0.5) -> dict[str, Any]:
    """Figures of how far ``replayed`` is from ``recorded``.

    ``identical``: same points, colours and normals byte for byte (each is also reported on its own:
    Open3D's normal estimation may differ in the last float32 bit between processes). Otherwise the symmetric mean
    nearest-neighbour distance (``chamfer_mm``, the paper's Chamfer definition: mean of both one-sided
    means) and the largest nearest-neighbour distance either way (``hausdorff_mm``);
    ``within_tolerance`` when identical or ``hausdorff_mm <= tolerance_mm``.
    """
    a = np.asarray(recorded.xyz, dtype=np.float64)
    b = np.asarray(replayed.xyz, dtype=np.float64)
    xyz_same, rgb_same = _same(recorded.xyz, replayed.xyz), _same(recorded.rgb, replayed.rgb)
    normals_same = _same(recorded.normals, replayed.normals)
    identical = xyz_same and rgb_same and normals_same
    out: dict[str, Any] = {"identical": bool(identical), "xyz_identical": bool(xyz_same),
                           "rgb_identical": bool(rgb_same), "normals_identical": bool(normals_same),
                           "points_recorded": int(len(a)), "points_replayed": int(len(b)),
                           "tolerance_mm": float(tolerance_mm)}
    na, nb = recorded.normals, replayed.normals
    if not normals_same and na is not None and nb is not None and na.shape == nb.shape:
        per_point = np.abs(np.asarray(na, np.float64) - np.asarray(nb, np.float64)).max(axis=1)
        out["normals_max_diff"] = float(per_point.max())
        # a normal from an ill-conditioned neighbourhood (near-degenerate covariance) turns a last-bit
        # difference into a visible one: say how many, not only the worst
        out["normals_fraction_beyond_1e-5"] = float(np.mean(per_point > 1e-5))
    if identical:
        out.update(chamfer_mm=0.0, hausdorff_mm=0.0, within_tolerance=True)
        return out
    if len(a) == 0 or len(b) == 0:
        out.update(chamfer_mm=None, hausdorff_mm=None, within_tolerance=False)
        return out
    d_ab = cKDTree(b).query(a)[0]
    d_ba = cKDTree(a).query(b)[0]
    chamfer = 0.5 * (float(d_ab.mean()) + float(d_ba.mean())) * 1e3
    hausdorff = max(float(d_ab.max()), float(d_ba.max())) * 1e3
    out.update(chamfer_mm=round(chamfer, 6), hausdorff_mm=round(hausdorff, 6),
               within_tolerance=bool(hausdorff <= tolerance_mm))
    if len(a) == len(b):
        out["max_pointwise_diff_mm"] = round(float(np.abs(a - b).max()) * 1e3, 9)
    return out

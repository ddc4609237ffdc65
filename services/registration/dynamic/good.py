"""GOOD: the Global Orthographic Object Descriptor (Kasaei et al., Pattern Recognition Letters 2016).

The paper (II-C-1) segments each view into regions, describes every region with GOOD for n = 10, 30 and 50
bins, and registers the top 3 most similar region pairs between neighbouring views. This module gives the
descriptor, a distance between descriptors, the region segmentation and that region pairing.

Descriptor, as in Kasaei's reference C++ (``SeyedHamidreza/GOOD_descriptor:src/good.cpp``):
1. Centre the points on their centroid; PCA of the covariance gives X = largest eigenvector, Y = middle,
   Z = X x Y (right-handed local reference frame).
2. Sign disambiguation: count points with x > t and x < -t (t = ``threshold``); likewise for y.
3. Project onto the YoZ, XoZ and XoY planes; each plane is a square of side (largest bbox side + 2 cm) centred
   on the centroid, split into n x n bins; each 2-D histogram is flattened row-major and normalised to sum 1.
4. Order: the projection of highest entropy first, then the other two by increasing variance of the
   histogram (bin index i + 1 as the value), exactly as the C++ ``objectViewHistogram``.

One deliberate deviation (documented in docs/dynamic-registration-blocks.md): the C++ multiplies the
projected x and y coordinates by a single s = Sx * Sy and only flips when the imbalance is >= N/10 points.
The eigenvector signs a solver returns are arbitrary, so that leaves the descriptor dependent on them (a
rotated copy of the same object can give a mirrored histogram). We instead orient each axis on its own
(X so that at least as many points lie at x > t as at x < -t, same for Y; exact ties broken by the sign of
the third moment) and rebuild Z = X x Y. That gives a unique right-handed frame, which is what makes the
descriptor rotation invariant as the paper claims.

``convention="colthurst"`` follows the paper authors' own Python (``toricolthurst/GOOD:good.py``) where it
differs in ways that matter for the numbers: t = 0.015 m by default, a sign that is +1 only if the count
difference is >= 5 points, a plane side l = 2 max|coord| with bins floor(n (c + l/2) / (l + 1e-4)), and the
two remaining projections ordered by *decreasing* variance with 0-based bin indices. Its frame comes from
Open3D's oriented bounding box; we use the PCA frame for both conventions (same axes up to order and sign,
and the sign is fixed per axis as above).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.cluster import KMeans

from services.registration.dynamic.fourpcs_common import PointCloudInputError, as_optional_rows, as_xyz

CONVENTIONS = ("kasaei", "colthurst")
_DEFAULT_THRESHOLD = {"kasaei": 0.0015, "colthurst": 0.015}
METRICS = ("chi2", "euclidean", "js")


def good_descriptor(points: np.ndarray, n_bins: int = 5, *, threshold: float | None = None,
                    convention: str = "kasaei") -> np.ndarray:
    """GOOD descriptor of a cloud: a float64 vector of length 3 n^2, each n^2 block summing to 1.

    ``threshold`` (m) defaults to the convention's own value (0.0015 Kasaei, 0.015 Colthurst). The descriptor
    is invariant to rotation and translation of ``points`` and (through the fixed plane margin) not to scale.
    """
    if convention not in CONVENTIONS:
        raise PointCloudInputError(f"unknown GOOD convention {convention!r}; use one of {CONVENTIONS}",
                                   code="bad_value", detail={"field": "convention"})
    if int(n_bins) < 1:
        raise PointCloudInputError("n_bins must be >= 1", code="bad_value", detail={"field": "n_bins"})
    n = int(n_bins)
    xyz = as_xyz(points, "points", min_points=3)
    t = _DEFAULT_THRESHOLD[convention] if threshold is None else float(threshold)
    local = good_reference_frame_coords(xyz, threshold=t, min_count=5 if convention == "colthurst" else 0)
    x, y, z = local[:, 0], local[:, 1], local[:, 2]
    if convention == "kasaei":
        side = float(np.max(local.max(axis=0) - local.min(axis=0))) + 0.02
        projections = [_hist_kasaei(y, z, side, n), _hist_kasaei(x, z, side, n), _hist_kasaei(x, y, side, n)]
        return _order_kasaei(projections)
    side = 2.0 * float(np.max(np.abs(local)))
    projections = [_hist_colthurst(x, y, side, n), _hist_colthurst(y, z, side, n),
                   _hist_colthurst(x, z, side, n)]
    return _order_colthurst(projections)


def good_reference_frame_coords(points: np.ndarray, *, threshold: float = 0.0015,
                                min_count: int = 0) -> np.ndarray:
    """Points expressed in GOOD's disambiguated PCA frame (origin at the centroid).

    ``min_count`` is the count margin for flipping an axis: 0 orients each axis towards the side with more
    points (our Kasaei variant); 5 is the Colthurst rule (positive only if #pos - #neg >= 5).
    """
    xyz = np.asarray(points, dtype=np.float64)
    centred = xyz - xyz.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred / xyz.shape[0])  # ascending eigenvalues
    axes = [vecs[:, 2].copy(), vecs[:, 1].copy()]
    for k in range(2):
        c = centred @ axes[k]
        pos = int(np.count_nonzero(c > threshold))
        neg = int(np.count_nonzero(c < -threshold))
        if min_count > 0:
            flip = (pos - neg) < min_count
        elif pos != neg:
            flip = neg > pos
        else:
            flip = float(np.sum(c**3)) < 0.0
        if flip:
            axes[k] = -axes[k]
    frame = np.column_stack([axes[0], axes[1], np.cross(axes[0], axes[1])])
    return centred @ frame


def good_distance(a: np.ndarray, b: np.ndarray, metric: str = "chi2") -> float:
    """Dissimilarity of two GOOD descriptors of the same length (0 = identical).

    - ``"chi2"`` (default): 0.5 sum (a - b)^2 / (a + b), the symmetric chi-squared histogram distance. Each
      normalised projection contributes at most 1, so the value lies in [0, 3] whatever n is; that is what
      lets ``top_region_pairs`` average distances over n = 10, 30 and 50.
    - ``"euclidean"``: the L2 distance, what the reference C++ ``computeDistanceBetweenProjections`` uses.
    - ``"js"``: Jensen-Shannon divergence (bits), summed over the three projections, also in [0, 3].
    """
    va, vb = np.asarray(a, dtype=np.float64).ravel(), np.asarray(b, dtype=np.float64).ravel()
    if va.shape != vb.shape:
        raise PointCloudInputError(f"descriptor lengths differ: {va.size} vs {vb.size}", code="bad_shape")
    if metric == "euclidean":
        return float(np.linalg.norm(va - vb))
    if metric == "chi2":
        s = va + vb
        nz = s > 0
        return float(0.5 * np.sum((va[nz] - vb[nz]) ** 2 / s[nz]))
    if metric == "js":
        m = 0.5 * (va + vb)
        return float(0.5 * (_kl_bits(va, m) + _kl_bits(vb, m)))
    raise PointCloudInputError(f"unknown metric {metric!r}; use one of {METRICS}", code="bad_value")


def segment_regions(points: np.ndarray, normals: np.ndarray | None = None, colors: np.ndarray | None = None,
                    *, n_regions: int = 6, normal_weight: float = 0.5, color_weight: float = 0.5,
                    min_points: int = 30, seed: int = 0) -> list[np.ndarray]:
    """Split a view into compact regions; returns one index array per region (largest first).

    The paper only says each view is "segmented into regions [23]". We use k-means (scikit-learn) on
    per-point features: the position scaled by the cloud's RMS radius (so the result does not depend on the
    object's size), plus the unit normal times ``normal_weight`` and the RGB in [0, 1] times
    ``color_weight``. Position keeps regions spatially compact - which is what lets the same part of the
    object fall into one region in two neighbouring views - while normals and colour split it along creases
    and print boundaries. Regions smaller than ``min_points`` are dropped.
    """
    xyz = as_xyz(points, "points", min_points=1)
    nrm = as_optional_rows(normals, xyz.shape[0], "normals")
    col = as_optional_rows(colors, xyz.shape[0], "colors")
    k = int(n_regions)
    if k < 1:
        raise PointCloudInputError("n_regions must be >= 1", code="bad_value", detail={"field": "n_regions"})
    if xyz.shape[0] < k:
        raise PointCloudInputError(f"{xyz.shape[0]} points cannot make {k} regions", code="too_few_points")
    centred = xyz - xyz.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum(centred**2, axis=1)))) or 1.0
    features = [centred / scale]
    if nrm is not None:
        features.append(normal_weight * nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12))
    if col is not None:
        features.append(color_weight * (col / 255.0 if col.max() > 1.0 else col))
    labels = KMeans(n_clusters=k, n_init=3, random_state=seed).fit_predict(np.hstack(features))
    regions = [np.flatnonzero(labels == i) for i in range(k)]
    regions = [r for r in regions if r.size >= min_points]
    return sorted(regions, key=lambda r: -r.size)


@dataclass(frozen=True)
class RegionPair:
    """A region of cloud A matched to a region of cloud B by GOOD similarity (smaller distance = closer)."""

    index_a: int
    index_b: int
    distance: float
    distances_per_n: tuple[float, ...]


def top_region_pairs(regions_a: list[np.ndarray], regions_b: list[np.ndarray], points_a: np.ndarray,
                     points_b: np.ndarray, n_values: tuple[int, ...] = (10, 30, 50), k: int = 3, *,
                     metric: str = "chi2", convention: str = "kasaei",
                     unique: bool = True) -> list[RegionPair]:
    """The ``k`` most similar (region of A, region of B) pairs by GOOD, most similar first.

    Each region is described with GOOD at every n in ``n_values`` (the paper's 10, 30, 50); a pair's distance
    is the mean of its per-n distances (chi2 keeps each in [0, 3], so no n dominates). With ``unique`` each
    region appears in at most one returned pair, so the k registrations the caller runs are different ones.
    """
    pa = as_xyz(points_a, "points_a")
    pb = as_xyz(points_b, "points_b")
    if not regions_a or not regions_b:
        return []
    desc_a = [[good_descriptor(pa[r], n, convention=convention) for n in n_values] for r in regions_a]
    desc_b = [[good_descriptor(pb[r], n, convention=convention) for n in n_values] for r in regions_b]
    per_n = np.array([[[good_distance(da[m], db[m], metric) for m in range(len(n_values))]
                       for db in desc_b] for da in desc_a])  # (A, B, len(n_values))
    mean = per_n.mean(axis=2)
    order = np.dstack(np.unravel_index(np.argsort(mean, axis=None, kind="stable"), mean.shape))[0]
    pairs: list[RegionPair] = []
    used_a: set[int] = set()
    used_b: set[int] = set()
    for i, j in order:
        if unique and (i in used_a or j in used_b):
            continue
        pairs.append(RegionPair(int(i), int(j), float(mean[i, j]), tuple(float(v) for v in per_n[i, j])))
        used_a.add(int(i))
        used_b.add(int(j))
        if len(pairs) == k:
            break
    return pairs


def _hist_kasaei(u: np.ndarray, v: np.ndarray, side: float, n: int) -> np.ndarray:
    """Normalised n x n histogram of (u, v) on a square of ``side`` centred at 0; outside points dropped."""
    interval = side / n
    iu = np.trunc((u + side / 2) / interval)
    iv = np.trunc((v + side / 2) / interval)
    keep = (iu >= 0) & (iu < n) & (iv >= 0) & (iv < n)
    hist = np.zeros((n, n))
    np.add.at(hist, (iu[keep].astype(int), iv[keep].astype(int)), 1.0)
    total = hist.sum()
    return (hist / total if total > 0 else hist).ravel()


def _hist_colthurst(u: np.ndarray, v: np.ndarray, side: float, n: int) -> np.ndarray:
    iu = np.clip(np.floor(n * (u + side / 2) / (side + 1e-4)).astype(int), 0, n - 1)
    iv = np.clip(np.floor(n * (v + side / 2) / (side + 1e-4)).astype(int), 0, n - 1)
    hist = np.zeros((n, n))
    np.add.at(hist, (iu, iv), 1.0)
    return (hist / hist.sum()).ravel()


def _entropy_bits(p: np.ndarray) -> float:
    nz = p[p > 0]
    return float(-np.sum(nz * np.log2(nz)))


def _variance(p: np.ndarray, one_based: bool) -> float:
    idx = np.arange(p.size, dtype=np.float64) + (1.0 if one_based else 0.0)
    mu = float(np.sum(idx * p))
    return float(np.sum((idx - mu) ** 2 * p))


def _order_kasaei(projections: list[np.ndarray]) -> np.ndarray:
    first = int(np.argmax([_entropy_bits(p) for p in projections]))
    a, b = [i for i in range(3) if i != first]
    if _variance(projections[a], True) > _variance(projections[b], True):
        a, b = b, a
    return np.concatenate([projections[first], projections[a], projections[b]])


def _order_colthurst(projections: list[np.ndarray]) -> np.ndarray:
    first = int(np.argmax([_entropy_bits(p) for p in projections]))
    a, b = [i for i in range(3) if i != first]
    if _variance(projections[a], False) < _variance(projections[b], False):
        a, b = b, a
    return np.concatenate([projections[first], projections[a], projections[b]])


def _kl_bits(p: np.ndarray, q: np.ndarray) -> float:
    nz = p > 0
    return float(np.sum(p[nz] * np.log2(p[nz] / q[nz])))

"""GeoGrasp's ranking terms, checked against a direct per-pair evaluation of the authors' formulas."""

from __future__ import annotations

import numpy as np

from services.grasp.candidates import CandidateRegion, surface_variation
from services.grasp.config import GraspPlannerConfig
from services.grasp.ranking import minmax_normalise, rank_region_pair


def _reference_rank(pa, na, da, ca, pb, nb, db, cb, axis):
    """The authors' formulas (GeoGrasp.cpp), one pair at a time, with x̂ = (x - min)/(max - min)."""
    def norm(v, x):
        return 0.0 if v.max() == v.min() else (x - v.min()) / (v.max() - v.min())
    out = {}
    for i in range(len(pa)):
        for j in range(len(pb)):
            line = (pb[j] - pa[i]) / np.linalg.norm(pb[j] - pa[i])
            cos_b = abs(line @ axis)
            a1, a2 = abs(line @ na[i]), abs(line @ nb[j])
            r1 = 2 - norm(da, da[i]) - norm(db, db[j]) - 10 * (cos_b - 0.2)
            r2 = 2 - norm(ca, ca[i]) - norm(cb, cb[j]) + a1 + a2 - abs(a1 - a2)
            out[(i, j)] = (1.5 * r1 + r2, r1, r2, np.linalg.norm(pb[j] - pa[i]), min(a1, a2))
    return out


def test_rank_matches_the_reference_formulas():
    rng = np.random.default_rng(0)
    na_, nb_ = 7, 9
    pts = np.vstack([rng.normal([0, -0.03, 0], 0.004, (na_, 3)), rng.normal([0, 0.03, 0], 0.004, (nb_, 3))])
    nrm = rng.normal(0, 0.3, (na_ + nb_, 3)) + np.vstack([np.tile([0, -1, 0], (na_, 1)), np.tile([0, 1, 0], (nb_, 1))])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    axis = np.array([0.0, 0.0, 1.0])
    a = CandidateRegion("y", -1, 0, np.arange(na_), rng.uniform(0, 0.1, na_), np.abs(pts[:na_, 2]))
    b = CandidateRegion("y", 1, na_, np.arange(na_, na_ + nb_), rng.uniform(0, 0.1, nb_), np.abs(pts[na_:, 2]))
    # a permissive config so every pair is ranked, not filtered
    cfg = GraspPlannerConfig(max_contact_angle_deg=90.0, r1_min=-100, r2_min=-100, max_grasp_line_tilt_deg=90.0)
    ranking = rank_region_pair(a, b, pts, nrm, axis, np.array([1.0, 0.0, 0.0]), cfg, top_k=na_ * nb_)
    ref = _reference_rank(pts[:na_], nrm[:na_], a.plane_distance, a.curvature,
                          pts[na_:], nrm[na_:], b.plane_distance, b.curvature, axis)
    assert len(ranking.best) == na_ * nb_
    for pair in ranking.best:
        rank, r1, r2, width, _ = ref[(pair.i, pair.j - na_)]
        assert np.isclose(pair.rank, rank) and np.isclose(pair.metrics["r1"], r1)
        assert np.isclose(pair.metrics["r2"], r2) and np.isclose(pair.metrics["width"], width)
    assert [p.rank for p in ranking.best] == sorted((p.rank for p in ranking.best), reverse=True)

    # with the default thresholds, every kept pair passes them and the counts add up
    strict = GraspPlannerConfig()
    r = rank_region_pair(a, b, pts, nrm, axis, np.array([1.0, 0.0, 0.0]), strict, top_k=na_ * nb_)
    for pair in r.best:
        _, r1, r2, width, min_cos = ref[(pair.i, pair.j - na_)]
        assert r1 >= 1 and r2 >= 1 and width <= 0.106 and min_cos >= np.cos(np.radians(20))
    assert len(r.best) + sum(r.rejected_counts.values()) == na_ * nb_
    n_valid = sum(1 for (rank, r1, r2, w, mc) in ref.values()
                  if r1 >= 1 and r2 >= 1 and w <= 0.106 and mc >= np.cos(np.radians(20)))
    assert len(r.best) == n_valid


def test_minmax_normalise_handles_constant_values():
    assert np.array_equal(minmax_normalise(np.full(4, 0.3)), np.zeros(4))
    assert np.allclose(minmax_normalise(np.array([1.0, 2.0, 3.0])), [0.0, 0.5, 1.0])


def test_surface_variation_is_zero_on_a_plane_and_grows_with_bending():
    from services.grasp.candidates import voxel_thin

    rng = np.random.default_rng(2)
    plane = np.column_stack([rng.uniform(-0.05, 0.05, (3000, 2)), np.zeros(3000)])
    assert np.allclose(surface_variation(plane, plane[:20], 0.01), 0.0, atol=1e-12)

    def sphere_curvature(radius):
        d = rng.normal(size=(8000, 3))
        s = radius * d / np.linalg.norm(d, axis=1, keepdims=True)
        thinned = s[voxel_thin(np.arange(len(s)), s, 0.0025)]  # as candidate_regions does
        return surface_variation(thinned, s[:30], 0.01)

    # a patch of radius a on a sphere of radius R has λmin/Σλ ≈ a²/(24 R²): ~4x larger at half the radius
    c2, c1 = sphere_curvature(0.02), sphere_curvature(0.01)
    assert np.all(c2 > 0.001) and np.all(c2 < 0.02)
    assert np.median(c1) > 2.5 * np.median(c2)

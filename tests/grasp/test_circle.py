"""Least-squares circle fits and the object-centre estimate used by the turn poses."""

from __future__ import annotations

import numpy as np
import pytest

from services.grasp.candidates import object_frame
from services.grasp.circle import estimate_object_center, fit_circle_2d, fit_circles_batched
from tests.grasp import shapes as S


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("arc_deg", [360.0, 180.0, 120.0])
def test_fit_recovers_a_known_centre_under_noise(seed, arc_deg):
    rng = np.random.default_rng(seed)
    center, r = rng.uniform(-0.5, 0.5, 2), 0.034
    t = rng.uniform(0, np.radians(arc_deg), 400) + rng.uniform(0, 2 * np.pi)
    pts = center + r * np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, 0.001, (400, 2))
    fit = fit_circle_2d(pts)
    assert fit is not None
    assert np.linalg.norm(fit.center - center) < 0.0005
    assert abs(fit.radius - r) < 0.0005
    assert 0.0007 < fit.rms < 0.0013  # the residual is the injected noise


def test_geometric_refinement_beats_the_algebraic_fit_on_a_short_noisy_arc():
    rng = np.random.default_rng(3)
    t = rng.uniform(0, np.radians(90), 300)
    pts = 0.05 * np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, 0.002, (300, 2))
    kasa = fit_circle_2d(pts, refine_iterations=0)
    refined = fit_circle_2d(pts)
    assert np.linalg.norm(refined.center) < np.linalg.norm(kasa.center)
    assert refined.rms <= kasa.rms + 1e-12


@pytest.mark.parametrize("pts", [np.zeros((0, 2)), np.ones((2, 2)), np.column_stack([np.arange(10.0), np.arange(10.0)]),
                                 np.full((5, 2), np.nan)])
def test_degenerate_inputs_give_no_circle(pts):
    assert fit_circle_2d(pts) is None


@pytest.mark.parametrize("seed", range(3))
def test_object_centre_of_a_partial_noisy_can_is_its_axis(seed):
    p, _ = S.soup_can(view_from=S.CAMERA, noise=0.001, seed=seed)
    frame = object_frame(p, np.array([0.0, 0.0, 1.0]))
    c_local, used = estimate_object_center(frame.local, frame.extents, 0.007, 12, 12, np.random.default_rng(seed))
    c = frame.to_base(c_local[None])[0]
    assert used >= 8
    assert np.linalg.norm(c[:2] - S.OBJECT_XY) < 0.0005


def test_batched_fit_matches_single_fits():
    rng = np.random.default_rng(11)
    groups, truth = [], []
    for _ in range(6):
        c, r = rng.uniform(-0.2, 0.2, 2), rng.uniform(0.01, 0.08)
        t = rng.uniform(0, rng.uniform(np.pi, 2 * np.pi), 150)
        groups.append(c + r * np.column_stack([np.cos(t), np.sin(t)]) + rng.normal(0, 0.0005, (150, 2)))
        truth.append(c)
    groups.append(np.column_stack([np.arange(5.0), np.arange(5.0)]))  # collinear: not a circle
    labels = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    centres, radii, ok = fit_circles_batched(np.vstack(groups), labels, len(groups), refine_iterations=8)
    assert ok.tolist() == [True] * 6 + [False]
    for k in range(6):
        single = fit_circle_2d(groups[k], refine_iterations=8)
        assert np.allclose(centres[k], single.center, atol=1e-7) and np.isclose(radii[k], single.radius)
        assert np.linalg.norm(centres[k] - truth[k]) < 0.0005

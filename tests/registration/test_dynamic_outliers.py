"""A view that disagrees with the others is found and left out (or re-registered), the model stays at the
true-pose fusion, and the report names the view; turn corrections beyond the turn accuracy are implausible."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from services.registration.dynamic.outliers import (
    OutlierConfig,
    implausible_edges,
    robust_threshold,
)


def test_the_robust_test_flags_one_view_far_from_the_others_and_not_the_noise():
    cfg = OutlierConfig()
    clean = [0.97, 0.95, 0.96, 0.98, 0.94, 0.97, 0.96, 0.95, 0.97, 0.96, 0.98, 0.95]
    assert min(clean) >= robust_threshold(clean, cfg)
    bad = clean[:5] + [0.60] + clean[6:]
    assert bad[5] < robust_threshold(bad, cfg) <= min(clean)
    # a thin or shiny object whose views all fit less: relative to its own views, nothing is an outlier
    low = [f - 0.3 for f in clean]
    assert min(low) >= robust_threshold(low, cfg)
    # noise-free views (every fitness ~1, MAD 0): a view 0.1 % worse is not an outlier, one 10 % worse is
    exact = [1.0, 0.9998] * 6
    assert 0.999 >= robust_threshold(exact, cfg) > 0.90


def test_a_turn_correction_beyond_the_turn_accuracy_is_implausible():
    from common.geometry import make_transform, rotation_about_axis
    from services.registration.dynamic.pair import PairResult

    def edge(k: int, deg: float) -> PairResult:
        T = make_transform(rotation_about_axis([0, 0, 1], np.radians(deg)), np.zeros(3))
        return PairResult(k, k + 1, k, T, 0.9, 0.001, 0.9, "turn4dof", "full", 0.1)

    results = [edge(0, 3.0), edge(1, -12.0), edge(2, 89.8), edge(3, 25.0)]
    flagged = implausible_edges(results, OutlierConfig())  # default: 6 deg x 5 sigma = 30 deg
    assert [e["edge"] for e in flagged] == [2] and flagged[0]["window_deg"] == 30.0
    tight = implausible_edges(results, OutlierConfig(turn_sigma_deg=2.0))  # a session stating 2 deg: 10 deg
    assert [e["edge"] for e in tight] == [1, 2, 3]


def _corrupt(view, how: str):
    """One view's cloud made wrong the way an upstream failure makes it."""
    from common.geometry import rotation_about_axis

    c = np.asarray(view.center, dtype=float)
    R = rotation_about_axis([0, 0, 1], np.radians(90.0))
    turned = ((view.xyz - c) @ R.T + c).astype(np.float32)
    if how == "turned_90":  # the cloud of another turn: the object 90 degrees off its commanded turn
        return replace(view, xyz=turned, normals=(view.normals @ R.T).astype(np.float32))
    # a scan fused with a wrong pose (a global result 90 degrees off, 15 mm up): the view holds its own points
    # and a misplaced copy, as in a failing run of a symmetric box
    extra = turned + np.array([0.0, 0.0, 0.015], dtype=np.float32)
    return replace(view, xyz=np.vstack([view.xyz, extra]), rgb=np.vstack([view.rgb, view.rgb]),
                   normals=np.vstack([view.normals, (view.normals @ R.T).astype(np.float32)]))


@pytest.fixture(scope="module")
def milk_scan():
    from bench.synthetic import synthetic_views

    return synthetic_views("milk", profile="hand-turned", seed=3, voxel=0.002)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["misplaced_scan", "turned_90"])
def test_a_corrupted_view_is_left_out_and_the_model_stays_at_the_true_pose_fusion(milk_scan, how):
    from bench.synthetic import oracle_poses
    from services.registration.dynamic.model import DynamicConfig, build_model, fuse
    from services.registration.evaluation import evaluate_model

    bad = 5
    views = list(milk_scan.views)
    views[bad] = _corrupt(views[bad], how)
    model = build_model(views, DynamicConfig())
    assert model.views_left_out == [views[bad].index]
    report = model.to_json()
    assert report["views_left_out"] == [bad] and report["outlier_views"]["left_out"][0]["view"] == bad
    assert report["accepted"] is True, report["why"]  # the eleven others agree
    gt = milk_scan.gt_points_view0(60_000)
    fig = evaluate_model(model.xyz, gt, align=True, init_T=np.eye(4))
    clean = milk_scan.views  # the true-pose fusion of the twelve uncorrupted views
    floor = evaluate_model(fuse(clean, oracle_poses(clean, gt), model.voxel).xyz, gt, align=True, init_T=np.eye(4))
    assert fig["chamfer_mm"] <= 1.3 * floor["chamfer_mm"], (fig["chamfer_mm"], floor["chamfer_mm"])


def test_when_no_two_views_agree_none_is_left_out_and_the_model_is_not_accepted():
    """Four views whose every turn is implausible (a 90-degree step against a 30-degree window): the outlier
    test flags them all. Nothing is left to register them against, so none is dropped; the model says why."""
    from common.geometry import make_transform, rotation_about_axis
    from services.registration.dynamic.configurations import AcceptCriteria, ConfigurationOutcome, shortfalls
    from services.registration.dynamic.outliers import handle_outlier_views
    from services.registration.dynamic.pair import PairResult
    from services.registration.dynamic.preprocess import preprocess

    scan = synthetic_views_cached(4)
    prep = preprocess(list(scan.views))
    turn = make_transform(rotation_about_axis([0, 0, 1], np.radians(90.0)), np.zeros(3))
    results = [PairResult(k, (k + 1) % 4, k, turn, 0.5, 0.001, 0.5, "turn4dof", "full", 0.1) for k in range(4)]
    poses = [np.eye(4) for _ in range(4)]
    out = handle_outlier_views(prep, poses, results, OutlierConfig())
    assert out.no_majority and out.outliers == [0, 1, 2, 3] and out.left_out == []
    outcome = ConfigurationOutcome(name="turn4dof", results=results, combined=None,  # type: ignore[arg-type]
                                   loop={"rotation_deg": 0.0, "translation_mm": 0.0},
                                   consistency={"min_posed_fitness": 1.0}, seconds=0.0, outliers=out)
    assert any("no two views agree" in why for why in shortfalls(outcome, AcceptCriteria()))


def synthetic_views_cached(views: int):
    from bench.synthetic import synthetic_views

    return synthetic_views("milk", views=views, scans_per_view=1, profile="ideal", seed=0, voxel=0.003)

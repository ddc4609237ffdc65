"""The 4-DoF turn stage recovers a known yaw + shift between two views, and the pair registration uses it
(path ``turn4dof``) when the turn is far from the commanded one, before any 6-DoF search."""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import invert, transform_error
from services.registration.dynamic.pair import PairConfig, PairJob, register_pair
from services.registration.dynamic.preprocess import Cloud, preprocess, prerotation
from services.registration.dynamic.turn4dof import TurnSearchConfig, known_turn, search_turn
from services.registration.dynamic.views import DynamicView, view_from_static
from tests.conftest import shared_data


def _cloud(v: DynamicView) -> Cloud:
    return Cloud(np.asarray(v.xyz, np.float32), np.asarray(v.rgb, np.uint8), np.asarray(v.normals, np.float32))


@pytest.fixture(scope="module")
def twin_pair():
    """Two twin views (3 scans each, D435 noise, hand-turned errors) of the milk carton ~45 degrees apart,
    no turn known."""
    shared_data("hope", "milk")
    from bench.scenario import simulated_views
    from services.registration.static import register_view

    frames = simulated_views("milk", views=2, scans_per_view=3, profile="hand-turned", seed=4, turn_deg=45.0)
    T0 = np.asarray(frames[0][0].meta["T_base_object_true"])
    T1 = np.asarray(frames[1][0].meta["T_base_object_true"])
    v0 = view_from_static(register_view(frames[0]), 0.0, 0)
    v1 = view_from_static(register_view(frames[1]), 0.0, 1)
    return v0, v1, T0 @ invert(T1)  # truth: view 1's points onto where they were in view 0


def test_turn_search_recovers_the_twin_turn(twin_pair):
    v0, v1, T_true = twin_pair
    axis = np.asarray(v0.table.normal)
    prior = prerotation(v1, v0.center, axis)  # centres stacked, no turn assumed
    res = search_turn(_cloud(v1), _cloud(v0), axis, v0.center, prior=prior)
    dt, dr = transform_error(res.T, T_true)
    # the truth is the objects' true poses; each view also carries its static stage's error (a few mm under
    # hand-turned errors, scans aimed at the estimated centre), so the budget is 5 mm, not the search's own
    assert dr < 1.5 and dt < 0.005, (dt, dr, res.yaw_deg)
    assert abs(abs(res.yaw_deg) - 45.0) < 6.0  # the achieved turn differs from 45 by the hand-turn error


@pytest.fixture(scope="module")
def castard_views():
    """Real D415 views 4, 5, 6 of the castard sequence (~16 degrees apart), base from the table, no turn known."""
    seq = shared_data("real_sequences", "castard_d415")
    from services.importer.base_frame import estimate_base_frame
    from services.importer.sources import parse_intrinsics, read_frames
    from services.registration.static import register_view

    frames = read_frames(seq, parse_intrinsics("597.522,597.522,312.885,239.870"))
    base = estimate_base_frame(frames)
    views = []
    for k in (4, 5, 6):
        frames[k].T_base_camera = base.T_base_camera
        views.append(view_from_static(register_view([frames[k]]), 0.0, len(views)))
    return views, base


def _moved_copy(target: Cloud, axis: np.ndarray, center: np.ndarray, cam: np.ndarray, yaw: float,
                shift: tuple[float, float, float]) -> tuple[Cloud, np.ndarray]:
    """``target`` turned by ``yaw`` about ``axis`` through ``center`` and shifted; only the points still facing
    the camera at ``cam`` are kept (self-occlusion) and 0.7 mm of noise is added, so the clouds differ."""
    T_move = known_turn(axis, center, yaw, shift)
    moved = target.transformed(T_move)
    facing = np.einsum("ij,ij->i", moved.normals, cam - moved.xyz) > 0
    moved = moved.subset(np.flatnonzero(facing))
    rng = np.random.default_rng(0)
    return Cloud((moved.xyz + rng.normal(0, 0.0007, moved.xyz.shape)).astype(np.float32), moved.rgb,
                 moved.normals), T_move


def test_pair_registration_finds_a_large_turn_without_6dof(castard_views):
    """A real view and its copy turned by 105 degrees, no turn commanded: the pair is found as a turn, without
    any 6-DoF search."""
    views, base = castard_views
    prep = preprocess(views)
    target = prep.views[1].reduced
    source, T_move = _moved_copy(target, prep.axis, prep.center, base.T_base_camera[:3, 3], 105.0, (0.01, -0.006, 0))

    def job(**cfg) -> PairJob:
        return PairJob(index=0, source_view=1, target_view=0, source=source, target=target, center=prep.center,
                       axis=prep.axis, config=PairConfig(**cfg))

    res = register_pair(job())
    dt, dr = transform_error(res.T, invert(T_move))
    assert dr < 1.0 and dt < 0.003, (dt, dr, res.path)
    assert res.path in ("prior", "turn4dof")
    assert not any(t["candidate"].startswith("global") for t in res.detail["tried"])  # no 6-DoF search
    assert all(t.get("tilt_deg", 0.0) < 10.0 for t in res.detail["tried"])  # a turn, not a tumble


def test_turn_only_pairs_drop_the_tilt_and_keep_the_turn(castard_views):
    """A fixed camera sees one table: with ``turn_only`` the result is a pure turn (no tilt about the table
    normal), with the yaw and the centre's motion of the 6-DoF fit; without it the measured tilt stays."""
    from common.geometry import make_transform, rotation_about_axis, yaw_deg_about
    from services.registration.dynamic.pair import tilt_deg

    views, base = castard_views
    prep = preprocess(views)
    target = prep.views[1].reduced
    source, T_move = _moved_copy(target, prep.axis, prep.center, base.T_base_camera[:3, 3], 15.0, (0.004, 0.002, 0))
    c = np.asarray(prep.center)
    tip = make_transform(rotation_about_axis(np.cross(prep.axis, [1.0, 0.0, 0.0]), np.radians(2.0)))
    tip[:3, 3] = c - tip[:3, :3] @ c  # tip the copy by 2 degrees about a horizontal line through the centre
    source = source.transformed(tip)
    results = {}
    for turn_only in (False, True):
        job = PairJob(index=0, source_view=1, target_view=0, source=source, target=target, center=prep.center,
                      axis=prep.axis, config=PairConfig(turn_only=turn_only))
        results[turn_only] = register_pair(job)
    six, four = results[False], results[True]
    assert 1.5 < tilt_deg(six.T, prep.axis) < 2.5  # the 6-DoF fit measures the tip
    assert tilt_deg(four.T, prep.axis) < 1e-6 and four.detail["turn_only"]["tilt_dropped_deg"] > 1.5
    assert abs(yaw_deg_about(prep.axis, four.T[:3, :3]) + 15.0) < 1.0  # the turn is kept
    moved = lambda T: T[:3, :3] @ c + T[:3, 3]  # noqa: E731
    assert np.linalg.norm(moved(four.T) - moved(six.T)) < 1e-6
    assert "turn_only" not in six.detail


def test_turn_search_recovers_a_known_yaw_and_shift_on_a_real_view(castard_views):
    """A real D415 view of the castard box and its copy moved by a known turn + shift (``_moved_copy``)."""
    views, base = castard_views
    view = views[1]
    target = _cloud(view)
    axis = np.asarray(view.table.normal)
    for yaw, shift in ((-38.0, (0.012, -0.008, 0.0)), (71.0, (-0.006, 0.015, 0.001))):
        moved, T_move = _moved_copy(target, axis, view.center, base.T_base_camera[:3, 3], yaw, shift)
        res = search_turn(moved, target, axis, view.center, config=TurnSearchConfig())
        dt, dr = transform_error(res.T, invert(T_move))
        assert dr < 1.0 and dt < 0.003, (yaw, dt, dr, res.yaw_deg)
        assert abs(res.yaw_deg + yaw) < 1.0


def test_the_turn_search_config_travels_to_workers():
    """Pair jobs go to registration workers over the wire: the nested 4-DoF config must survive the trip."""
    from common.codec import decode, encode
    from services.registration.pair_wire import pair_job_from_message, pair_job_message

    rng = np.random.default_rng(0)
    cloud = Cloud(rng.random((60, 3)).astype(np.float32), rng.integers(0, 255, (60, 3)).astype(np.uint8),
                  np.tile(np.float32([0, 0, 1]), (60, 1)))
    cfg = PairConfig(turn_search=TurnSearchConfig(yaw_step_deg=5.0, icp_voxels=(0.004, 0.002),
                                                  icp_corr_factor=(2.0, 1.5)), max_turn_tilt_deg=8.0)
    job = PairJob(index=3, source_view=4, target_view=3, source=cloud, target=cloud, center=np.zeros(3),
                  axis=np.array([0.0, 0.0, 1.0]), config=cfg)
    back = pair_job_from_message(decode(encode(pair_job_message(job))))
    assert back.config == cfg and isinstance(back.config.turn_search, TurnSearchConfig)


def test_a_prior_path_result_far_from_its_prior_is_not_a_turn():
    """A result 87 degrees away from its prior (a box face matched onto its neighbour) fails the prior path's
    check like a tumble does; the turn errors a prior carries pass."""
    from common.geometry import make_transform, rotation_about_axis
    from services.registration.dynamic.pair import is_turn_near_prior

    axis, cfg = np.array([0.0, 0.0, 1.0]), PairConfig()
    prior = known_turn(axis, np.array([0.5, 0.0, 0.1]), -40.0, (0.0, 0.0, 0.0))
    for yaw, ok in ((15.0, True), (-30.0, True), (-87.5, False), (60.0, False)):
        T = known_turn(axis, np.array([0.5, 0.0, 0.1]), yaw, (0.003, 0.0, 0.0)) @ prior
        assert is_turn_near_prior(T, prior, axis, cfg) is ok, yaw
    tipped = make_transform(rotation_about_axis([1.0, 0.0, 0.0], np.radians(12.0))) @ prior
    assert not is_turn_near_prior(tipped, prior, axis, cfg)

"""The odometry-setting bench: the default variant is the shipped static stage, a variant runs the static stage
with its own setting, and an unknown variant is refused."""

from __future__ import annotations

import pytest

from bench import reconstruct_odometry as ro
from services.registration import api
from services.registration.api import StaticConfig, register_view, relative_pose_errors


@pytest.fixture(scope="module")
def view():
    from bench.scenario import simulated_views

    return simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]


def test_the_default_variant_is_the_shipped_static_stage(view):
    row = ro.measure_views([view], StaticConfig(), "default")
    shipped = max(e[0] for e in relative_pose_errors(register_view(view, StaticConfig()), view))
    assert row["pairs"] == 2 and row["scans_left_out"] == 0
    assert row["static_max_trans_err_mm"] == pytest.approx(shipped, abs=1e-3)
    assert row["odometry_cpu_s"] > 0


def test_a_variant_runs_the_static_stage_with_its_setting(view, monkeypatch):
    seen = []
    real = register_view

    def spy(frames, config):  # noqa: ANN001, ANN202
        seen.append(config)
        return real(frames, config)

    monkeypatch.setattr(api, "register_view", spy)
    row = ro.measure_views([view], StaticConfig(), "fine_only")
    assert [c.odometry_iterations for c in seen] == [(0, 0, 1)]
    assert row["pairs"] == 2


def test_an_unknown_variant_is_refused(view):
    with pytest.raises(ValueError, match="unknown odometry variant"):
        ro.measure_views([view], StaticConfig(), "fastest")

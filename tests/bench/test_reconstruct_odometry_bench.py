"""The odometry-variant bench: the default variant is the shipped static stage, a variant really swaps the odometry
(and puts it back), and an unknown variant is refused."""

from __future__ import annotations

import numpy as np
import pytest

from bench import reconstruct_odometry as ro
from services.registration.static import StaticConfig, register_view
from services.registration.static import default_profile as dp
from services.registration.static.pose_errors import relative_pose_errors


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


def test_the_tensor_variant_runs_the_tensor_odometry_and_restores_the_legacy_one(view, monkeypatch):
    calls = []
    tensor = ro.tensor_odometry

    def counted(*args, **kwargs):  # noqa: ANN002, ANN003
        calls.append(kwargs.get("step", 1))
        return tensor(*args, **kwargs)

    monkeypatch.setattr(ro, "tensor_odometry", counted)
    legacy = dp._odometry
    row = ro.measure_views([view], StaticConfig(), "tensor")
    assert calls and set(calls) == {1}  # the forward pass, at full resolution, once per pair at least
    assert row["pairs"] == 2 and np.isfinite(row["static_max_trans_err_mm"])
    assert dp._odometry is legacy
    calls.clear()
    ro.measure_views([view], StaticConfig(), "tensor_seed")
    assert calls and set(calls) == {2}  # the reverse seed, at half resolution
    assert dp.reverse_seed.__module__ == dp.__name__


def test_an_unknown_variant_is_refused(view):
    with pytest.raises(ValueError, match="unknown odometry variant"):
        ro.measure_views([view], StaticConfig(), "fastest")

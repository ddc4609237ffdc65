"""The default static profile on the ``realistic`` twin (issue 15): the arm's prior is 1-3 mm / 0.3-1 deg off
per scan, and the RGB-D odometry must still converge to the scans' true relative poses.

The view below is the one ``objscan bench static --quick`` measures for orange_juice (seed 13): with the
odometry pyramid (8, 4, 1) it stopped 3.9 mm off along the camera slide/tilt direction and passed its
check; with (16, 16, 1) every scan is within 1 mm.
"""

from __future__ import annotations

from services.registration.static import StaticConfig, register_view
from services.registration.static.pose_errors import prior_pose_errors, relative_pose_errors


def test_realistic_view_registers_within_1mm():
    from services.sim.scenario import simulated_views

    frames = simulated_views("orange_juice", views=1, scans_per_view=3, profile="realistic", seed=13)[0]
    prior = prior_pose_errors(frames)
    assert max(e[0] for e in prior) > 2.0  # the arm's poses alone are millimetres off: there is work to do
    result = register_view(frames, StaticConfig())
    errors = relative_pose_errors(result, frames)
    assert [s.path for s in result.scans[1:]] == ["local", "local"]  # the fast path, no global fallback
    assert max(e[0] for e in errors) < 1.0, errors
    assert max(e[1] for e in errors) < 0.2, errors


def test_odometry_that_stalls_from_the_prior_is_reseeded():
    """milk, realistic seed 0, view 0 (``objscan bench reconstruct``'s first view): from the arm's prior
    (6.9 mm / 1.3 deg off) the forward RGB-D odometry of scan 2 onto scan 0 stalled at 5.7 mm and passed its
    check. Seeded by the reverse odometry (scan 0 onto scan 2, half resolution) it converges."""
    from services.sim.scenario import simulated_views

    frames = simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]
    assert max(e[0] for e in prior_pose_errors(frames)) > 5.0  # a prior far enough off to stall the odometry
    result = register_view(frames, StaticConfig())
    errors = relative_pose_errors(result, frames)
    assert [s.path for s in result.scans[1:]] == ["local", "local"]
    assert max(e[0] for e in errors) < 1.0, errors
    assert max(e[1] for e in errors) < 0.2, errors

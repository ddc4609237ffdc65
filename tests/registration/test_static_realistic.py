"""The default static profile on the ``realistic`` twin: the arm's prior is 1-3 mm / 0.3-1 deg off
per scan, and the RGB-D odometry must still converge to the scans' true relative poses.

The view below is the one ``objscan bench static --quick`` measures for orange_juice (seed 13): with the
odometry pyramid (8, 4, 1) it stopped 3.9 mm off along the camera slide/tilt direction and passed its
check; with (16, 16, 1) every scan is within 1 mm.
"""

from __future__ import annotations

import numpy as np

from services.registration.static import StaticConfig, register_view
from services.registration.static.pose_errors import prior_pose_errors, relative_pose_errors


def test_realistic_view_registers_within_1mm():
    from bench.scenario import simulated_views

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
    from bench.scenario import simulated_views

    frames = simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]
    assert max(e[0] for e in prior_pose_errors(frames)) > 5.0  # a prior far enough off to stall the odometry
    result = register_view(frames, StaticConfig())
    errors = relative_pose_errors(result, frames)
    assert [s.path for s in result.scans[1:]] == ["local", "local"]
    assert max(e[0] for e in errors) < 1.0, errors
    assert max(e[1] for e in errors) < 0.2, errors


def _prepared_milk_view():  # noqa: ANN202 - (frames, prepared scans, cfg)
    from bench.scenario import simulated_views
    from common.geometry import transform_points
    from services.registration.static.default_profile import crop_to_roi, prepare
    from services.registration.static.scans import centre_depth, load_scans

    frames = simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]
    cfg = StaticConfig()
    scans = load_scans(frames, cfg)
    seed_base = transform_points(scans[0].T_believed, np.array([[0.0, 0.0, centre_depth(frames[0], cfg)]]))[0]
    crop_to_roi(scans, seed_base, cfg)
    return frames, prepare(scans, frames, cfg), cfg, seed_base


def test_a_pose_slid_along_the_table_passes_the_scan_check_and_is_refined_on_the_object():
    """A realistic milk acquisition's view 10: scan 1's odometry stalled 1.5 deg / 9.4 mm (at the object) off
    and still scored above the true pose on the whole-scan check, because a camera turned about the table's
    normal through its own centre leaves the table where it was. Here the same kind of slide (2 deg, ~10 mm at the
    object) is put on a true pose: the scan check passes it, the object refinement brings it back within
    1 mm, and a true pose is left as it is (no fitness to gain)."""
    from common.geometry import invert, rotation_about_line, transform_points
    from services.registration.static import default_profile as dp

    frames, data, cfg, seed_base = _prepared_milk_view()
    true = invert(frames[0].T_base_camera_true) @ frames[1].T_base_camera_true  # scan 1 into scan 0's camera
    prior = invert(frames[0].T_base_camera) @ frames[1].T_base_camera
    normal_c0 = frames[0].T_base_camera_true[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    slid = rotation_about_line(normal_c0, np.zeros(3), np.radians(2.0)) @ true
    centre_c1 = transform_points(invert(frames[1].T_base_camera_true), seed_base[None])

    def object_error_mm(T: np.ndarray) -> float:
        return 1000.0 * float(np.linalg.norm(transform_points(T, centre_c1) - transform_points(true, centre_c1)))

    assert object_error_mm(slid) > 6.0
    assert dp._check(data[1].check, data[0].check, slid, prior, cfg)[1]  # the whole-scan check cannot tell
    out = dp._local(data[1], data[0], slid, prior, "rgbd_odometry", cfg)
    assert out.verified and out.method == "rgbd_odometry+object_icp"
    assert object_error_mm(out.T) < 1.0, object_error_mm(out.T)
    assert dp.refine_on_object(data[1], data[0], true, prior, cfg) is None
    off = dp._local(data[1], data[0], slid, prior, "rgbd_odometry", StaticConfig(object_refine=False))
    assert off.verified and off.method == "rgbd_odometry" and object_error_mm(off.T) > 6.0

"""The RGB-D odometry on the view's region-of-interest rectangle (``odometry_window_margin``, off by default) covers
every ROI pixel, moves the principal point by the rectangle's corner, and lands where the whole-image odometry
lands on a pair it converges on.

The rectangle (``static/odometry_window.py``) is the union of the scans' ROI pixel bounding boxes plus a margin,
snapped to the coarsest pyramid level. A rectangle that cut an ROI pixel, or a principal point left unshifted,
would show as a different pose. (Over whole sessions it costs accuracy: the table outside it pins the slide;
docs/static-registration.md.)
"""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import invert, transform_error, transform_points
from services.registration.static import StaticConfig
from services.registration.static import default_profile as dp
from services.registration.static.odometry import pinhole
from services.registration.static.odometry_window import (
    ImageWindow,
    odometry_window,
    pyramid_alignment,
    roi_window,
)
from services.registration.static.scans import centre_depth, load_scans

W, H = 640, 480
WINDOWED = StaticConfig(odometry_window_margin=16)


def inside(window: ImageWindow, pixel: np.ndarray, image_width: int) -> np.ndarray:
    """Which flat pixel indices (row * ``image_width`` + col) lie inside ``window``."""
    row, col = np.divmod(np.asarray(pixel, dtype=np.int64), image_width)
    return (col >= window.x0) & (col < window.x1) & (row >= window.y0) & (row < window.y1)


def _flat(rows: list[int], cols: list[int]) -> np.ndarray:
    return np.asarray(rows, dtype=np.int64) * W + np.asarray(cols, dtype=np.int64)


def test_the_window_is_the_union_of_the_scans_boxes_grown_and_snapped_outward():
    a, b = _flat([140, 300], [70, 200]), _flat([200, 470], [150, 600])
    w = roi_window([a, b], W, H, margin=16, align=8)
    # union: rows 140..470, cols 70..600; grown by 16 then snapped outward to multiples of 8, clipped to the image
    assert w == ImageWindow(x0=48, y0=120, x1=624, y1=480)
    assert all(v % 8 == 0 for v in (w.x0, w.y0, w.x1, w.y1))
    assert inside(w, np.concatenate([a, b]), W).all()
    assert roi_window([np.empty(0, np.int64)], W, H, 16, 8) == ImageWindow(0, 0, W, H)
    with pytest.raises(ValueError):
        roi_window([a], W, H, margin=-1, align=8)


def test_the_alignment_follows_both_odometry_pyramids():
    cfg = StaticConfig()  # forward (16, 16, 1) at full resolution, seed (16, 16) at half: coarsest pixels 4 px
    assert pyramid_alignment(cfg) == 4
    assert pyramid_alignment(cfg.with_(odometry_seed_step=4)) == 8
    assert pyramid_alignment(cfg.with_(odometry_seed_iterations=None, odometry_iterations=(8, 8, 8, 1))) == 8


def test_no_region_of_interest_or_no_margin_keeps_the_whole_image():
    px = [_flat([200, 300], [200, 300])]
    assert odometry_window(px, W, H, True, WINDOWED) == ImageWindow(184, 184, 320, 320)
    assert odometry_window(px, W, H, False, WINDOWED) is None  # no seed point / roi_radius None
    assert odometry_window(px, W, H, True, StaticConfig()) is None  # the shipped setting: the whole image
    assert odometry_window([_flat([0, H - 1], [0, W - 1])], W, H, True, WINDOWED) is None  # fills the image
    with pytest.raises(ValueError):
        StaticConfig(odometry_window_margin=-1)


@pytest.fixture(scope="module")
def milk_view():
    """milk, realistic twin, seed 0, view 0 (``bench reconstruct``'s first view): scans cropped to the ROI."""
    from bench.scenario import simulated_views

    frames = simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]
    cfg = WINDOWED
    scans = load_scans(frames, cfg)
    seed_base = transform_points(scans[0].T_believed, np.array([[0.0, 0.0, centre_depth(frames[0], cfg)]]))[0]
    dp.crop_to_roi(scans, seed_base, cfg)
    return frames, scans, seed_base, cfg


def test_the_view_window_covers_every_roi_pixel_and_is_smaller_than_the_image(milk_view):
    frames, scans, seed_base, cfg = milk_view
    w = dp.view_window(scans, frames, seed_base, cfg)
    assert w is not None
    align = pyramid_alignment(cfg)
    assert all(v % align == 0 for v in (w.x0, w.y0)) and w.x1 <= W and w.y1 <= H
    for s in scans:
        assert inside(w, s.pts_cam.pixel, W).all()
    assert w.width * w.height < 0.9 * W * H  # the lever: fewer pixels for the odometry
    assert dp.view_window(scans, frames, None, cfg) is None  # no seed point: no ROI, the whole image


def test_the_window_intrinsics_move_the_principal_point_by_its_corner(milk_view):
    frames, scans, seed_base, cfg = milk_view
    w = dp.view_window(scans, frames, seed_base, cfg)
    k = frames[0].intrinsics
    for step in (1, 2):
        p = pinhole(frames[0], step, w)
        cx, cy = p.get_principal_point()
        assert (p.width, p.height) == (len(range(w.x0, w.x1, step)), len(range(w.y0, w.y1, step)))
        assert cx == pytest.approx((k.cx - w.x0) / step) and cy == pytest.approx((k.cy - w.y0) / step)


def test_the_windowed_odometry_lands_where_the_whole_image_odometry_lands(milk_view):
    """Scan 1 onto scan 0 (prior 3 mm / 1.5 deg off): the reverse seed then the forward pass, on the window and on
    the whole image, agree to a few hundredths of a millimetre; with the principal point left unshifted the same
    windowed images put the scan centimetres off."""
    frames, scans, seed_base, cfg = milk_view
    window = dp.view_window(scans, frames, seed_base, cfg)
    whole, cut = dp.prepare(scans, frames, cfg), dp.prepare(scans, frames, cfg, window)
    prior = invert(frames[0].T_base_camera) @ frames[1].T_base_camera
    true = invert(frames[0].T_base_camera_true) @ frames[1].T_base_camera_true

    def local(data: list[dp.PriorScan]) -> np.ndarray:
        ok, T = dp._odometry(data[1], data[0], dp.reverse_seed(data[1], data[0], prior, cfg), cfg)
        assert ok
        return T

    T_whole, T_cut = local(whole), local(cut)
    assert transform_error(T_whole, true)[0] < 0.5e-3  # the whole-image odometry converges here
    m, deg = transform_error(T_cut, T_whole)
    assert m < 0.1e-3 and deg < 0.02, (m * 1e3, deg)

    unshifted = dp.prepare(scans, frames, cfg, window)
    for s in unshifted:
        s.intrinsic = pinhole(frames[0], cfg.odometry_step)  # the whole image's principal point
    ok, T_bad = dp._odometry(unshifted[1], unshifted[0], prior, cfg)
    assert not ok or transform_error(T_bad, true)[0] > 5e-3

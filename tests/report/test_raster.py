"""The CPU point renderer: pinhole projection, z-buffer, orbit cameras and the colormap."""

from __future__ import annotations

import numpy as np
import pytest

from services.report import RasterCamera, ReportError, colormap, orbit_camera, render_points

WHITE = (255, 255, 255)


def camera_at_origin(w: int = 64, h: int = 48) -> RasterCamera:
    return RasterCamera(np.eye(4), 50.0, 50.0, w / 2.0, h / 2.0, w, h)


def test_point_lands_on_its_pinhole_pixel():
    cam = camera_at_origin()
    # x = 0.1, z = 1 -> u = 50 * 0.1 + 32 = 37; y = -0.2 -> v = -10 + 24 = 14
    img = render_points(np.array([[0.1, -0.2, 1.0]]), np.array([[10, 200, 30]]), cam, radius_px=0)
    hit = np.argwhere((img != WHITE).any(axis=2))
    assert hit.tolist() == [[14, 37]]
    assert img[14, 37].tolist() == [10, 200, 30]


def test_nearer_point_wins_whatever_the_order():
    cam = camera_at_origin()
    xyz = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 3.0]])
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255]])
    for perm in ([0, 1, 2], [2, 1, 0], [1, 0, 2]):
        img = render_points(xyz[perm], rgb[perm], cam, radius_px=2)
        assert img[24, 32].tolist() == [0, 255, 0]


def test_points_behind_the_camera_and_nan_are_dropped():
    cam = camera_at_origin()
    img = render_points(np.array([[0.0, 0.0, -1.0], [np.nan, 0.0, 1.0]]), None, cam)
    assert (img == WHITE).all()


def test_splat_radius_covers_a_disk():
    cam = camera_at_origin()
    img = render_points(np.array([[0.0, 0.0, 1.0]]), np.array([[0, 0, 0]]), cam, radius_px=3)
    covered = int((img != WHITE).any(axis=2).sum())
    assert 25 <= covered <= 49  # a round splat: more than a plus, less than the 7x7 square


def test_orbit_camera_centres_and_fits_the_object():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1.0, 1.0, size=(5000, 3)) * [0.05, 0.05, 0.15] + [0.6, 0.0, 0.1]  # inside r = 0.2
    for az, el in ((0, 20), (90, 20), (200, 60)):
        cam = orbit_camera(pts.mean(axis=0), 0.2, az, el, 200, 160, fill=0.8)
        img = render_points(pts, None, cam, radius_px=1)
        ys, xs = np.nonzero((img != WHITE).any(axis=2))
        assert abs(xs.mean() - 100) < 6 and abs(ys.mean() - 80) < 6
        assert xs.min() > 0 and xs.max() < 199 and ys.min() > 0 and ys.max() < 159
    # world up shows up in the image: the higher point is drawn nearer the top
    cam = orbit_camera(np.zeros(3), 0.2, 30, 10, 200, 160)
    img = render_points(np.array([[0.0, 0.0, 0.1], [0.0, 0.0, -0.1]]), np.array([[255, 0, 0], [0, 0, 255]]), cam)
    red_v = np.argwhere((img == [255, 0, 0]).all(axis=2))[:, 0].mean()
    blue_v = np.argwhere((img == [0, 0, 255]).all(axis=2))[:, 0].mean()
    assert red_v < blue_v


def test_colormap_ends_and_clipping():
    c = colormap(np.array([-1.0, 0.0, 0.5, 1.0, 9.0]), 0.0, 1.0)
    assert c[0].tolist() == c[1].tolist() == [68, 1, 84]
    assert c[3].tolist() == c[4].tolist() == [253, 231, 37]
    assert c.dtype == np.uint8 and c[2].tolist() == [33, 144, 141]


def test_bad_inputs_are_typed_errors():
    with pytest.raises(ReportError):
        render_points(np.zeros((3, 2)), None, camera_at_origin())
    with pytest.raises(ReportError):
        render_points(np.zeros((3, 3)), np.zeros((2, 3)), camera_at_origin())
    with pytest.raises(ReportError):
        orbit_camera(np.zeros(3), 0.0, 0, 0)

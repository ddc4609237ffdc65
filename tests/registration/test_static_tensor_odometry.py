"""The tensor odometry backend (``odometry_backend="tensor"``) minimises the legacy odometry's objective: from the same
start it lands where the legacy lands, and the way its inputs are prepared is what makes it do so.

Open3D's tensor odometry called with its own defaults (7 cm outlier truncation, equal photometric/depth weights,
Huber losses, no blur) minimises a different objective and stops millimetres to centimetres off the legacy on
plain shapes (docs/static-registration.md); ``tensor_odometry.py`` prepares images and parameters as the legacy
does. A start in the wrong direction (target to source) or a convention slip shows here as a pose millimetres
away from the legacy's.
"""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import invert, transform_error, transform_points
from services.registration.static import StaticConfig
from services.registration.static import default_profile as dp
from services.registration.static.scans import centre_depth, load_scans
from services.registration.static.tensor_odometry import (
    INTENSITY_WEIGHT,
    TensorPyramid,
    tensor_rgbd_image,
    tensor_rgbd_odometry,
)

TENSOR = StaticConfig(odometry_backend="tensor")
LEGACY = StaticConfig(odometry_backend="legacy")


def test_the_tensor_backend_is_the_default_and_an_unknown_backend_is_refused():
    assert StaticConfig().odometry_backend == "tensor"
    with pytest.raises(ValueError, match="odometry_backend"):
        StaticConfig(odometry_backend="gpu")


def test_the_tensor_image_is_prepared_as_the_legacy_prepares_it():
    """Depth in metres with invalid pixels (and their blurred neighbours) at 0, intensity normalised to a mean of
    0.5 over the valid pixels and scaled to the legacy's photometric weight."""
    from common.messages import Intrinsics, RGBDFrame

    depth = np.full((24, 32), 500, dtype=np.uint16)
    depth[10, 10] = 0  # a hole
    depth[:, 28:] = 5000  # beyond depth_max
    color = np.zeros((24, 32, 3), dtype=np.uint8)
    color[:, :16] = 60
    color[:, 16:] = 180
    frame = RGBDFrame(color=color, depth=depth, depth_scale=0.001, T_base_camera=np.eye(4),
                      intrinsics=Intrinsics(width=32, height=24, fx=30.0, fy=30.0, cx=16.0, cy=12.0))
    pyramid = tensor_rgbd_image(frame, step=1, depth_min=0.1, depth_max=1.2, levels=2)
    assert len(pyramid.levels) == 2
    d, g = (np.squeeze(pyramid.levels[0].depth.as_tensor().numpy()),
            pyramid.levels[0].color.as_tensor().numpy()[:, :, 0])
    assert d.dtype == np.float32 and d[5, 5] == pytest.approx(0.5)  # metres, not millimetres
    assert (d[9:12, 9:12] == 0).all() and d[9, 13] == pytest.approx(0.5)  # the hole and its 3 x 3 neighbours
    assert (d[:, 27:] == 0).all()  # beyond depth_max, and the column next to it
    assert g[d > 0].mean() == pytest.approx(0.5 * INTENSITY_WEIGHT, rel=0.02)
    assert g[5, 3] < g[5, 25]  # dark stays dark
    # the coarser level: 2 x 2 block means, a block touching a dropped pixel dropped (the legacy pyramid)
    d1 = np.squeeze(pyramid.levels[1].depth.as_tensor().numpy())
    assert d1.shape == (12, 16) and d1[2, 2] == pytest.approx(0.5)
    assert (d1[4:6, 4:6] == 0).all() and d1[4, 6] == pytest.approx(0.5) and (d1[:, 13:] == 0).all()


@pytest.fixture(scope="module")
def milk_pairs():
    """milk, realistic twin, seed 0, view 0 (``bench reconstruct``'s first view), scans cropped to the ROI, both
    backends' images; per scan pair the reverse seed of the legacy pass (the shipped start)."""
    from bench.scenario import simulated_views

    frames = simulated_views("milk", views=1, scans_per_view=3, profile="realistic", seed=0)[0]
    legacy_cfg = LEGACY
    scans = load_scans(frames, legacy_cfg)
    seed_base = transform_points(scans[0].T_believed, np.array([[0.0, 0.0, centre_depth(frames[0], legacy_cfg)]]))[0]
    dp.crop_to_roi(scans, seed_base, legacy_cfg)
    return frames, dp.prepare(scans, frames, legacy_cfg), dp.prepare(scans, frames, TENSOR)


@pytest.mark.parametrize("j", [1, 2])
def test_the_tensor_odometry_lands_where_the_legacy_lands(milk_pairs, j):
    """From the same start (the legacy's reverse seed) the forward pass of each backend; both reach the truth's
    neighbourhood and agree to a few tenths of a millimetre. Started in the wrong direction (the inverse, a
    target-to-source start) the tensor pass lands millimetres away: the agreement is not slack."""
    frames, legacy, tensor = milk_pairs
    cfg = LEGACY
    prior = invert(frames[0].T_base_camera) @ frames[j].T_base_camera
    true = invert(frames[0].T_base_camera_true) @ frames[j].T_base_camera_true
    start = dp.reverse_seed(legacy[j], legacy[0], prior, cfg)

    ok_l, T_legacy = dp._odometry(legacy[j], legacy[0], start, cfg)
    ok_t, T_tensor = dp._odometry(tensor[j], tensor[0], start, TENSOR)
    assert ok_l and ok_t
    assert transform_error(T_legacy, true)[0] < 1.0e-3
    m, deg = transform_error(T_tensor, T_legacy)
    assert m < 0.3e-3 and deg < 0.03, (m * 1e3, deg)

    _, T_wrong = tensor_rgbd_odometry(tensor[j].image, tensor[0].image, tensor[j].intrinsic, invert(start),
                                      iterations=cfg.odometry_iterations, max_depth_diff=cfg.odometry_max_depth_diff,
                                      depth_max=cfg.depth_max)
    assert transform_error(T_wrong, T_legacy)[0] > 2.0e-3


def test_the_tensor_pair_runs_through_the_pipeline(milk_pairs):
    """Both passes on the tensor backend, checked and refined as the legacy's: scan 1 within 1 mm of the truth."""
    frames, _, tensor = milk_pairs
    prior = invert(frames[0].T_base_camera) @ frames[1].T_base_camera
    true = invert(frames[0].T_base_camera_true) @ frames[1].T_base_camera_true
    out = dp.register_pair(tensor[1], tensor[0], prior, TENSOR, seed=0)
    assert out.verified and out.method.startswith("rgbd_odometry")
    assert transform_error(out.T, true)[0] < 1.0e-3
    assert isinstance(tensor[1].image, TensorPyramid)

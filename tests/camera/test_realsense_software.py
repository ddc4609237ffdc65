"""The realsense backend against a software D435 (pyrealsense2 software_device) with known ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from bench.software_d435 import SoftwareD435, SoftwareD435Spec, d435_depth_intrinsics, d435_T_color_depth
from common.geometry import invert
from common.messages import Intrinsics
from services.camera.errors import BadFrameError, CaptureTimeout, NoDeviceError
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.realsense import RealSenseCamera, RealSenseCameraConfig
from tests.camera.scene import BOX_COLOR, BOX_Z, WALL_Z, render, to_units
from tests.conftest import shared_data

pytestmark = pytest.mark.timeout(120)

DEPTH_SCALE = 0.0001  # not the D435 default, so a backend that assumed 0.001 would fail


def _spec(width: int, height: int, depth_scale: float = DEPTH_SCALE) -> SoftwareD435Spec:
    return SoftwareD435Spec(color_intrinsics=d435_color_intrinsics(width, height),
                            depth_intrinsics=d435_depth_intrinsics(width, height),
                            T_color_depth=d435_T_color_depth(), depth_scale=depth_scale, serial="4242")


def _capture(spec: SoftwareD435Spec, source, config: RealSenseCameraConfig | None = None, T=None):
    sw = SoftwareD435(spec)
    config = config or RealSenseCameraConfig(width=spec.color_intrinsics.width,
                                             height=spec.color_intrinsics.height, warmup_frames=2)
    with sw.streaming(source), RealSenseCamera(config, device=sw.device) as cam:
        frame = cam.capture(T)
        info = cam.info()
    return frame, info


@pytest.mark.parametrize("size", [(640, 480), (848, 480)])
def test_depth_is_aligned_to_color_with_injected_intrinsics(size):
    spec = _spec(*size)
    depth_m, _ = render(spec.depth_intrinsics, np.eye(4))            # what the depth imager sees
    T_color_depth = spec.T_color_depth
    expected_m, color = render(spec.color_intrinsics, T_color_depth)  # what aligned depth must be
    T = np.eye(4)
    T[:3, 3] = (0.3, 0.0, 0.5)
    frame, info = _capture(spec, (to_units(depth_m, DEPTH_SCALE), color), T=T)

    ci = spec.color_intrinsics
    assert frame.intrinsics == ci
    assert frame.depth_scale == pytest.approx(DEPTH_SCALE, rel=1e-6)
    assert frame.depth.dtype == np.uint16 and frame.depth.shape == (ci.height, ci.width)
    np.testing.assert_array_equal(frame.color, color)
    np.testing.assert_array_equal(frame.T_base_camera, T)
    assert frame.meta["pose_source"] == "given" and frame.seq == 0
    assert info["serial"] == "4242" and info["depth_scale"] == pytest.approx(DEPTH_SCALE)

    got_m = frame.depth * frame.depth_scale
    valid = (got_m > 0) & (expected_m > 0)
    assert valid.mean() > 0.9  # the depth imager's wider field of view covers the color image
    err = np.abs(got_m - expected_m)[valid]
    assert np.mean(err < 0.002) > 0.99, f"median error {np.median(err)} m"

    # the red box in the color image must carry the box's depth, pixel for pixel
    box = np.all(frame.color == BOX_COLOR, axis=-1)
    on_box = np.abs(got_m[box] - BOX_Z) < 0.002
    assert on_box.mean() > 0.97
    # ... which the raw, unaligned depth image does not do (the check can fail)
    raw_on_box = np.abs(depth_m[box] - BOX_Z) < 0.002
    assert raw_on_box.mean() < 0.6


def test_real_aligned_frame_passes_through_unchanged():
    """A real D4xx frame (already aligned) injected with identical intrinsics comes back as it went in."""
    root = shared_data("rgbd", "tabletop_uoc")
    p = json.loads((root / "camera_params.json").read_text())
    intr = Intrinsics(width=p["img_width"], height=p["img_height"], fx=p["fx"], fy=p["fy"],
                      cx=p["x_offset"], cy=p["y_offset"])
    color = np.asarray(Image.open(root / "000003-color.png").convert("RGB"), dtype=np.uint8)
    depth = np.asarray(Image.open(root / "000003-depth.png")).astype(np.uint16)
    spec = SoftwareD435Spec(color_intrinsics=intr, depth_intrinsics=intr, T_color_depth=np.eye(4),
                            depth_scale=0.001)
    frame, _ = _capture(spec, (depth, color))
    assert frame.intrinsics == intr
    np.testing.assert_array_equal(frame.color, color)
    both = (frame.depth > 0) & (depth > 0)
    assert both.sum() > 0.9 * (depth > 0).sum()
    assert np.mean(frame.depth[both] == depth[both]) > 0.95


def _noisy_wall(spec: SoftwareD435Spec, sigma_m: float):
    """A flat wall with fresh Gaussian depth noise in every frame."""
    di, ci = spec.depth_intrinsics, spec.color_intrinsics
    color = np.full((ci.height, ci.width, 3), 128, np.uint8)
    rng = np.random.default_rng(7)

    def source(i):
        depth = WALL_Z + rng.normal(0.0, sigma_m, (di.height, di.width))
        return to_units(depth, spec.depth_scale), color

    return source


def _centre_std(frame) -> tuple[float, float]:
    h, w = frame.depth.shape
    crop = frame.depth[h // 4: 3 * h // 4, w // 4: 3 * w // 4].astype(float) * frame.depth_scale
    crop = crop[crop > 0]
    return float(crop.std()), float(crop.mean())


def test_spatial_and_temporal_filters_reduce_noise_without_bias():
    # D435 default units: the filters' edge thresholds are in depth units, and 4 mm of noise at 0.1 mm
    # units would look like edges to them
    spec = _spec(640, 480, depth_scale=0.001)
    base = dict(width=640, height=480, warmup_frames=2)
    raw, _ = _capture(spec, _noisy_wall(spec, 0.004), RealSenseCameraConfig(**base))
    spatial, _ = _capture(spec, _noisy_wall(spec, 0.004), RealSenseCameraConfig(**base, spatial_filter=True))
    temporal, _ = _capture(spec, _noisy_wall(spec, 0.004),
                           RealSenseCameraConfig(**base, temporal_filter=True, frames_per_capture=5))
    raw_std, raw_mean = _centre_std(raw)
    assert raw_std > 0.003
    # rs.align keeps the nearest of the depth pixels landing on one color pixel: a slight pull towards
    # the camera (measured -2.7 mm at 4 mm noise); the spatial filter pushes the other way (+4 mm measured)
    assert abs(raw_mean - WALL_Z) < 0.005
    for frame, name, gain in ((spatial, "spatial", 0.25), (temporal, "temporal", 0.6)):
        std, mean = _centre_std(frame)
        assert std < gain * raw_std, name
        assert abs(mean - WALL_Z) < 0.005, name
        assert frame.meta["filters"] == [name]


def test_each_capture_is_a_fresh_frame():
    spec = _spec(640, 480)
    di, ci = spec.depth_intrinsics, spec.color_intrinsics
    color = np.zeros((ci.height, ci.width, 3), np.uint8)

    def source(i):
        return np.full((di.height, di.width), 8000 + i, np.uint16), color

    sw = SoftwareD435(spec)
    with sw.streaming(source), RealSenseCamera(RealSenseCameraConfig(warmup_frames=3), device=sw.device) as cam:
        a, b = cam.capture(), cam.capture()
    assert b.meta["frame_number"] > a.meta["frame_number"] >= 4  # after the warm-up
    assert int(np.median(b.depth[b.depth > 0])) > int(np.median(a.depth[a.depth > 0]))
    assert (a.seq, b.seq) == (0, 1)
    assert a.meta["pose_source"] == "unknown"
    np.testing.assert_array_equal(a.T_base_camera, np.eye(4))


def test_silent_device_times_out():
    sw = SoftwareD435(_spec(640, 480))
    cam = RealSenseCamera(RealSenseCameraConfig(warmup_frames=0, timeout_ms=300), device=sw.device)
    with cam, pytest.raises(CaptureTimeout) as err:
        cam.capture()
    assert err.value.code == "timeout"


def test_software_device_rejects_frames_of_the_wrong_size():
    sw = SoftwareD435(_spec(640, 480))
    with pytest.raises(BadFrameError):
        sw.push(np.zeros((480, 848), np.uint16), np.zeros((480, 640, 3), np.uint8))
    with pytest.raises(BadFrameError):
        sw.push(np.zeros((480, 640), np.float32), np.zeros((480, 640, 3), np.uint8))


def test_no_device_attached_gives_a_clear_error():
    import pyrealsense2 as rs

    if len(rs.context().query_devices()) > 0:
        pytest.skip("a RealSense camera is attached to this machine")
    cam = RealSenseCamera(RealSenseCameraConfig())
    with pytest.raises(NoDeviceError) as err:
        cam.connect()
    assert err.value.code == "no_device"
    assert "USB" in err.value.message
    assert not cam.is_connected


def test_pose_conventions_of_the_emulated_extrinsics():
    """The emulator's extrinsics follow T_color_depth (depth -> color), as librealsense reports them."""
    spec = _spec(640, 480)
    sw = SoftwareD435(spec)
    depth_profile = sw._depth_profile
    color_profile = sw._color_profile
    ext = depth_profile.get_extrinsics_to(color_profile)
    R = np.asarray(ext.rotation).reshape(3, 3).T
    np.testing.assert_allclose(R, spec.T_color_depth[:3, :3])
    np.testing.assert_allclose(ext.translation, spec.T_color_depth[:3, 3], atol=1e-7)
    back = color_profile.get_extrinsics_to(depth_profile)
    np.testing.assert_allclose(back.translation, invert(spec.T_color_depth)[:3, 3], atol=1e-7)

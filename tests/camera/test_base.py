"""The shared camera plumbing: config parsing, the factory, presets, frame and pose checks."""

from __future__ import annotations

import numpy as np
import pytest

from bench.software_d435 import d435_depth_intrinsics, d435_T_color_depth
from common.messages import Intrinsics, RGBDFrame, d435_intrinsics
from services.camera import (
    BadFrameError,
    CameraConfigError,
    RealSenseCameraConfig,
    ReplayCameraConfig,
    SimCameraConfig,
    check_frame,
    check_pose,
    config_from_dict,
    make_camera,
)
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.realsense import RealSenseCamera
from services.camera.replay import ReplayCamera


def test_config_from_dict_picks_the_backend_and_rejects_typos(tmp_path):
    cfg = config_from_dict({"backend": "realsense", "width": 848, "spatial_filter": True})
    assert isinstance(cfg, RealSenseCameraConfig) and cfg.width == 848 and cfg.spatial_filter
    assert cfg.backend == "realsense"
    assert isinstance(config_from_dict({"backend": "sim"}), SimCameraConfig)
    replay = config_from_dict({"backend": "replay", "session_dir": str(tmp_path)})
    assert isinstance(replay, ReplayCameraConfig) and replay.session_dir == tmp_path
    for bad in ({"backend": "kinect"}, {}, {"backend": "realsense", "widht": 848},
                {"backend": "realsense", "width": 0}, {"backend": "realsense", "warmup_frames": -1},
                {"backend": "replay"}, {"backend": "sim", "timeout_s": 0}):
        with pytest.raises(CameraConfigError) as err:
            config_from_dict(bad)
        assert err.value.code == "bad_config"


def test_make_camera_builds_the_named_backend(tmp_path):
    assert isinstance(make_camera(RealSenseCameraConfig()), RealSenseCamera)
    cam = make_camera({"backend": "replay", "session_dir": str(tmp_path)})
    assert isinstance(cam, ReplayCamera) and not cam.is_connected
    assert cam.info()["backend"] == "replay"


def test_d435_presets():
    assert d435_color_intrinsics() == Intrinsics(width=640, height=480, fx=615.0, fy=615.0, cx=320.0, cy=240.0)
    wide = d435_color_intrinsics(848, 480)
    assert (wide.fx, wide.cx, wide.cy) == (615.0, 424.0, 240.0)
    assert d435_color_intrinsics() is not d435_color_intrinsics()  # callers may mutate their copy
    assert d435_depth_intrinsics().fx < d435_color_intrinsics().fx  # depth sees wider than color
    np.testing.assert_allclose(d435_T_color_depth()[:3, :3], np.eye(3))
    with pytest.raises(CameraConfigError):
        d435_color_intrinsics(1280, 720)
    # one D435 colour model: the twin's small test renders scale it, an unset frame carries it
    assert d435_intrinsics(320, 240) == Intrinsics(width=320, height=240, fx=307.5, fy=307.5, cx=160.0, cy=120.0)
    frame = RGBDFrame(color=np.zeros((480, 640, 3), np.uint8), depth=np.zeros((480, 640), np.uint16),
                      T_base_camera=np.eye(4))
    assert frame.intrinsics == d435_color_intrinsics()


def _frame(**kw) -> RGBDFrame:
    fields = dict(color=np.zeros((4, 6, 3), np.uint8), depth=np.zeros((4, 6), np.uint16), depth_scale=0.001,
                  intrinsics=Intrinsics(width=6, height=4, fx=5.0, fy=5.0, cx=3.0, cy=2.0),
                  T_base_camera=np.eye(4))
    fields.update(kw)
    return RGBDFrame(**fields)


def test_check_frame():
    assert check_frame(_frame(), expected_size=(6, 4)) is not None
    bad = [
        _frame(intrinsics=Intrinsics(width=640, height=480, fx=5.0, fy=5.0, cx=3.0, cy=2.0)),
        _frame(intrinsics=Intrinsics(width=6, height=4, fx=0.0, fy=5.0, cx=3.0, cy=2.0)),
        _frame(color=np.zeros((4, 6, 4), np.uint8)),
        _frame(depth=np.zeros((4, 6), np.int32)),
        _frame(depth_scale=float("nan")),
        _frame(T_base_camera=np.eye(3)),
        _frame(color=np.zeros((0, 0, 3), np.uint8), depth=np.zeros((0, 0), np.uint16)),
        "frame",
    ]
    for frame in bad:
        with pytest.raises(BadFrameError):
            check_frame(frame)
    with pytest.raises(BadFrameError):
        check_frame(_frame(), expected_size=(640, 480))


def test_check_pose():
    assert check_pose(None) is None
    T = np.eye(4)
    T[:3, 3] = (0.1, 0.2, 0.3)
    out = check_pose(T.tolist())
    assert out.dtype == np.float64 and np.array_equal(out, T)

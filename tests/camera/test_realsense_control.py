"""Camera control on the software D435: exposure and white balance settled then locked across views and
recorded in meta, the visual preset applied, reconnect with hardware_reset after repeated timeouts, serial
selection. The software device emulates auto exposure that drifts frame to frame (bench/software_d435.py)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from bench.software_d435 import SoftwareD435, SoftwareD435Spec
from services.camera.errors import CameraConfigError, CaptureTimeout, NoDeviceError
from services.camera.realsense import RealSenseCamera, RealSenseCameraConfig
from services.camera.realsense.camera import _rs, choose_serial

pytestmark = pytest.mark.timeout(120)


def _pair(spec: SoftwareD435Spec) -> tuple[np.ndarray, np.ndarray]:
    di, ci = spec.depth_intrinsics, spec.color_intrinsics
    return np.full((di.height, di.width), 600, np.uint16), np.full((ci.height, ci.width, 3), 120, np.uint8)


def _views(lock: bool, n: int = 4) -> tuple[list[dict], list[float], SoftwareD435]:
    """``n`` captures a few frames apart (the arm moving between views): exposure meta and mean colour."""
    sw = SoftwareD435(SoftwareD435Spec(exposure_scales_color=True))
    cfg = RealSenseCameraConfig(warmup_frames=6, lock_exposure=lock)
    metas, means = [], []
    with sw.streaming(_pair(sw.spec)), RealSenseCamera(cfg, device=sw.device) as cam:
        for _ in range(n):
            time.sleep(0.25)  # ~7 frames at 30 fps: the auto loop (when on) moves on meanwhile
            f = cam.capture()
            metas.append(f.meta["exposure"])
            means.append(float(f.color.mean()))
    return metas, means, sw


def test_exposure_and_white_balance_are_locked_across_views_and_recorded():
    metas, means, sw = _views(lock=True)
    first = metas[0]
    assert first["locked"] and first["source"] == "metadata"
    assert first["exposure_us"] > 0 and first["white_balance_k"] > 0
    for m in metas:  # the same settings are in force in every view, and the frames say so
        assert m["frame_exposure_us"] == first["exposure_us"] and m["frame_white_balance_k"] == first["white_balance_k"]
        assert {k: m[k] for k in ("exposure_us", "gain", "white_balance_k")} == \
               {k: first[k] for k in ("exposure_us", "gain", "white_balance_k")}
    assert max(means) - min(means) < 0.5  # so the images are exposed alike
    o = _rs().option
    assert sw._color_sensor.get_option(o.enable_auto_exposure) == 0
    assert sw._color_sensor.get_option(o.enable_auto_white_balance) == 0


def test_without_the_lock_the_exposure_drifts_between_views():
    """The control group: the emulated auto loop really changes exposure between views (so the test above
    would fail if the lock were not applied)."""
    metas, means, _ = _views(lock=False)
    assert not metas[0]["locked"]
    assert len({m["frame_exposure_us"] for m in metas}) > 1
    assert max(means) - min(means) > 2.0


def test_visual_preset_is_applied_and_unknown_presets_refused():
    sw = SoftwareD435()
    rs = _rs()
    with sw.streaming(_pair(sw.spec)), RealSenseCamera(RealSenseCameraConfig(warmup_frames=1), device=sw.device) as cam:
        f = cam.capture()
        assert cam.info()["visual_preset"] == "high_accuracy"
    assert sw._depth_sensor.get_option(rs.option.visual_preset) == float(int(rs.rs400_visual_preset.high_accuracy))
    assert f.meta["visual_preset"] == "high_accuracy"
    with pytest.raises(CameraConfigError):
        RealSenseCameraConfig(visual_preset="sharpest")


def test_reconnects_with_hardware_reset_after_repeated_timeouts():
    sw = SoftwareD435()
    cfg = RealSenseCameraConfig(warmup_frames=3, timeout_ms=300, timeouts_before_reset=2, reset_wait_s=0.0)
    resets = []
    with sw.streaming(_pair(sw.spec)), RealSenseCamera(cfg, device=sw.device) as cam:
        locked = cam.capture().meta["exposure"]

        def fake_usb_reset(device):  # the fake: what a real power cycle does, the stream comes back
            resets.append(device)
            sw.resume()

        cam._hardware_reset = fake_usb_reset
        sw.stall()
        f = cam.capture()  # timeout, timeout, reset + reopen, frame
        assert len(resets) == 1 and cam.reconnects == 1 and f.meta["reconnects"] == 1
        again = f.meta["exposure"]
        assert {k: again[k] for k in ("exposure_us", "white_balance_k", "locked")} == \
               {k: locked[k] for k in ("exposure_us", "white_balance_k", "locked")}  # same exposure after it
        sw.stall()
        cam._hardware_reset = lambda device: resets.append(device)  # this time the camera stays gone
        with pytest.raises(CaptureTimeout):
            cam.capture()
        assert len(resets) == 2


def test_no_reset_when_disabled():
    sw = SoftwareD435()
    cfg = RealSenseCameraConfig(warmup_frames=1, timeout_ms=200, timeouts_before_reset=0)
    with sw.streaming(_pair(sw.spec)), RealSenseCamera(cfg, device=sw.device) as cam:
        cam.capture()
        sw.stall()
        with pytest.raises(CaptureTimeout):
            cam.capture()
        assert cam.reconnects == 0


def test_serial_selection():
    assert choose_serial(["111", "222"], "222") == "222"
    assert choose_serial(["111"], None) == "111"
    with pytest.raises(NoDeviceError) as e:
        choose_serial(["111", "222"], None)
    assert e.value.code == "ambiguous_camera" and e.value.detail["attached"] == ["111", "222"]
    with pytest.raises(NoDeviceError) as e:
        choose_serial(["111"], "333")
    assert e.value.code == "no_device"

"""The realsense backend playing back a .db3 recording made from a software D435."""

from __future__ import annotations

import numpy as np
import pytest

from bench.software_d435 import SoftwareD435Spec, d435_depth_intrinsics, d435_T_color_depth, record_db3
from services.camera.errors import CameraError, EndOfReplay, ReplayDataError
from services.camera.intrinsics import d435_color_intrinsics
from services.camera.realsense import RealSenseCamera, RealSenseCameraConfig
from tests.camera.scene import BOX_COLOR, BOX_Z, render, to_units

pytestmark = pytest.mark.timeout(120)

SPEC = SoftwareD435Spec(color_intrinsics=d435_color_intrinsics(640, 480),
                        depth_intrinsics=d435_depth_intrinsics(640, 480),
                        T_color_depth=d435_T_color_depth(), depth_scale=0.0005)
OFFSETS_M = (0.0, 0.05, 0.10)  # the scene moves away from the camera by this much in frames 0, 1, 2


def _frames():
    out = []
    for k, dz in enumerate(OFFSETS_M):
        T_shift = np.eye(4)
        T_shift[2, 3] = dz  # world -> camera: a camera further back sees everything dz deeper
        depth_m, _ = render(SPEC.depth_intrinsics, T_shift)
        _, color = render(SPEC.color_intrinsics, SPEC.T_color_depth @ T_shift)
        color[:8, :8] = k  # a per-frame tag in the corner
        out.append((to_units(depth_m, SPEC.depth_scale), color))
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    return record_db3(tmp_path_factory.mktemp("db3") / "session.db3", _frames(), SPEC)


def _play(path, **kw):
    cam = RealSenseCamera(RealSenseCameraConfig(playback_file=str(path), timeout_ms=3000, **kw))
    frames = []
    with cam:
        while True:
            try:
                frames.append(cam.capture())
            except EndOfReplay as exc:
                assert exc.code == "end_of_replay"
                break
        info = cam.info()
    return frames, info


def test_playback_serves_every_recorded_frame_in_order_then_ends(recording):
    frames, info = _play(recording)
    assert len(frames) == len(OFFSETS_M)
    assert info["playback_file"] == str(recording)
    assert info["depth_scale"] == pytest.approx(SPEC.depth_scale)
    for k, (frame, dz) in enumerate(zip(frames, OFFSETS_M, strict=True)):
        assert frame.seq == k
        assert frame.intrinsics == SPEC.color_intrinsics
        assert frame.depth_scale == pytest.approx(SPEC.depth_scale)
        assert frame.meta["source"] == "playback"
        assert np.all(frame.color[:8, :8] == k)
        box = np.all(frame.color == BOX_COLOR, axis=-1)  # aligned: the red box carries the box depth
        z = frame.depth[box] * frame.depth_scale
        assert np.mean(np.abs(z - (BOX_Z + dz)) < 0.002) > 0.97
    stamps = [f.stamp for f in frames]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)


def test_playback_is_deterministic(recording):
    a, _ = _play(recording)
    b, _ = _play(recording)
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.depth, fb.depth)
        np.testing.assert_array_equal(fa.color, fb.color)
        assert fa.stamp == fb.stamp


def test_missing_playback_file(tmp_path):
    cam = RealSenseCamera(RealSenseCameraConfig(playback_file=str(tmp_path / "nope.db3")))
    with pytest.raises(ReplayDataError) as err:
        cam.connect()
    assert err.value.code == "bad_replay" and "does not exist" in err.value.message


def test_corrupt_playback_file(tmp_path):
    bad = tmp_path / "corrupt.db3"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    cam = RealSenseCamera(RealSenseCameraConfig(playback_file=str(bad)))
    with pytest.raises(ReplayDataError) as err:
        cam.connect()
    assert err.value.code == "bad_replay" and str(bad) in err.value.message
    assert not cam.is_connected


def test_playback_file_must_be_a_recording(tmp_path):
    other = tmp_path / "frames.png"
    other.write_bytes(b"not a recording")
    with pytest.raises(ReplayDataError):
        RealSenseCamera(RealSenseCameraConfig(playback_file=str(other))).connect()


def test_recording_needs_a_db3_name(tmp_path):
    with pytest.raises(CameraError) as err:
        record_db3(tmp_path / "x.bag", _frames()[:1], SPEC)
    assert err.value.code == "bad_config"

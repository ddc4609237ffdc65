"""The replay backend serves a recorded session folder in order and fails clearly on bad data."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from common.geometry import look_at
from common.messages import Intrinsics, RGBDFrame
from common.session_folder import scan_dir, write_scan, write_session
from services.camera import make_camera
from services.camera.errors import EndOfReplay, NotConnectedError, ReplayDataError
from services.camera.replay import ReplayCamera, ReplayCameraConfig
from tests.conftest import shared_data

VIEWS, SCANS = 2, 3


def _pose(view: int, scan: int) -> np.ndarray:
    eye = np.array([0.36 + 0.25 * np.cos(0.4 * scan), 0.25 * np.sin(0.4 * scan), 0.3 + 0.01 * view])
    return look_at(eye, [0.36, 0.0, 0.05])


def _frame(view: int, scan: int, intr: Intrinsics, depth=None, color=None) -> RGBDFrame:
    h, w = intr.height, intr.width
    if depth is None:
        depth = np.full((h, w), 400 + 10 * (view * SCANS + scan), np.uint16)
    if color is None:
        color = np.zeros((h, w, 3), np.uint8)
        color[..., 0], color[..., 1] = view, scan
    truth = _pose(view, scan)
    truth[:3, 3] += 0.003  # the sim's true pose differs from the belief
    return RGBDFrame(color=color, depth=depth, depth_scale=0.001, intrinsics=intr, T_base_camera=_pose(view, scan),
                     stamp=100.0 + view * SCANS + scan, seq=view * SCANS + scan, T_base_camera_true=truth,
                     meta={"scan_pose": f"pose_{scan}"})


def _session(root, intr=None, views=VIEWS, scans=SCANS):
    intr = intr or Intrinsics(width=64, height=48, fx=60.0, fy=60.0, cx=32.0, cy=24.0)
    for v in range(views):
        for s in range(scans):
            write_scan(root, v, s, _frame(v, s, intr))
    write_session(root, {"object": "test", "views": [{"index": v, "commanded_turn_deg": 30.0 * v}
                                                     for v in range(views)]})
    return root


def test_frames_come_in_order_with_the_recorded_poses_then_end(tmp_path):
    cam = ReplayCamera(ReplayCameraConfig(session_dir=_session(tmp_path)))
    with pytest.raises(NotConnectedError):
        cam.capture()
    served = []
    with cam:
        assert cam.remaining == VIEWS * SCANS
        for _ in range(VIEWS * SCANS):
            served.append(cam.capture(np.eye(4)))  # the pose passed in is ignored
        with pytest.raises(EndOfReplay) as err:
            cam.capture()
        assert err.value.code == "end_of_replay"
        assert cam.info()["recorded_frames"] == VIEWS * SCANS
    order = [(f.meta["replay"]["view"], f.meta["replay"]["scan"]) for f in served]
    assert order == [(v, s) for v in range(VIEWS) for s in range(SCANS)]
    for f, (v, s) in zip(served, order, strict=True):
        np.testing.assert_allclose(f.T_base_camera, _pose(v, s))
        assert f.T_base_camera_true is not None and not np.allclose(f.T_base_camera_true, f.T_base_camera)
        assert f.meta["pose_source"] == "recorded" and f.meta["requested_pose_ignored"] is True
        assert f.meta["scan_pose"] == f"pose_{s}"
        assert int(f.depth[0, 0]) == 400 + 10 * (v * SCANS + s)
        assert tuple(f.color[0, 0]) == (v, s, 0)
        assert f.seq == v * SCANS + s and f.stamp == 100.0 + v * SCANS + s


def test_loop_starts_over(tmp_path):
    with make_camera({"backend": "replay", "session_dir": str(_session(tmp_path, views=1, scans=2)),
                      "loop": True}) as cam:
        scans = [cam.capture().meta["replay"]["scan"] for _ in range(5)]
    assert scans == [0, 1, 0, 1, 0]


def test_real_frames_replay_pixel_identical(tmp_path):
    root = shared_data("rgbd", "tabletop_uoc")
    p = json.loads((root / "camera_params.json").read_text())
    intr = Intrinsics(width=p["img_width"], height=p["img_height"], fx=p["fx"], fy=p["fy"],
                      cx=p["x_offset"], cy=p["y_offset"])
    originals = []
    for k in range(3):
        color = np.asarray(Image.open(root / f"00000{k}-color.png").convert("RGB"), dtype=np.uint8)
        depth = np.asarray(Image.open(root / f"00000{k}-depth.png")).astype(np.uint16)
        write_scan(tmp_path, 0, k, _frame(0, k, intr, depth=depth, color=color))
        originals.append((color, depth))
    with ReplayCamera(ReplayCameraConfig(session_dir=tmp_path)) as cam:  # no session.json: views inferred
        for color, depth in originals:
            f = cam.capture()
            np.testing.assert_array_equal(f.color, color)
            np.testing.assert_array_equal(f.depth, depth)
            assert f.intrinsics == intr


def test_incomplete_scans_are_skipped(tmp_path):
    _session(tmp_path, views=1, scans=2)
    (scan_dir(tmp_path, 0, 1) / "meta.json").unlink()  # a crash before meta.json: not a real scan
    with ReplayCamera(ReplayCameraConfig(session_dir=tmp_path)) as cam:
        assert cam.capture().meta["replay"]["scan"] == 0
        with pytest.raises(EndOfReplay):
            cam.capture()


@pytest.mark.parametrize("damage", ["corrupt_color", "missing_depth", "corrupt_meta", "size_mismatch"])
def test_damaged_scan_gives_a_clear_error_at_its_turn(tmp_path, damage):
    _session(tmp_path, views=1, scans=2)
    d = scan_dir(tmp_path, 0, 1)
    if damage == "corrupt_color":
        (d / "color.png").write_bytes(b"\x89PNG garbage")
    elif damage == "missing_depth":
        (d / "depth.png").unlink()
    elif damage == "corrupt_meta":
        (d / "meta.json").write_text("{not json")
    else:
        Image.fromarray(np.zeros((10, 10), np.uint16)).save(d / "depth.png")
    with ReplayCamera(ReplayCameraConfig(session_dir=tmp_path)) as cam:
        cam.capture()
        with pytest.raises(ReplayDataError) as err:
            cam.capture()
    assert err.value.code == "bad_replay"
    assert str(d) in err.value.message and err.value.detail["scan"] == 1


def test_missing_or_empty_session_folder(tmp_path):
    with pytest.raises(ReplayDataError) as err:
        ReplayCamera(ReplayCameraConfig(session_dir=tmp_path / "nope")).connect()
    assert err.value.code == "bad_replay" and "does not exist" in err.value.message
    (tmp_path / "empty" / "view_00").mkdir(parents=True)
    cam = ReplayCamera(ReplayCameraConfig(session_dir=tmp_path / "empty"))
    with pytest.raises(ReplayDataError) as err:
        cam.connect()
    assert "no complete scan" in err.value.message and not cam.is_connected


def test_concurrent_captures_get_distinct_frames(tmp_path):
    import asyncio

    cam = ReplayCamera(ReplayCameraConfig(session_dir=_session(tmp_path)))

    async def main():
        await cam.aconnect()
        return await asyncio.gather(*(cam.acapture() for _ in range(VIEWS * SCANS)))

    frames = asyncio.run(main())
    assert sorted(f.meta["replay"]["index"] for f in frames) == list(range(VIEWS * SCANS))
    assert cam.info()["frames"] == VIEWS * SCANS

"""The png_folder camera backend (a backend is one folder plus one registry line):
it plays a folder of colour/depth PNG pairs with the given intrinsics, in the unit and as a real camera
service process answering captures over Zenoh."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from services.camera import make_camera
from services.camera.base import POSE_SOURCE_KEY
from services.camera.errors import CameraConfigError, EndOfReplay
from services.camera.png_folder import PngFolderCamera, PngFolderCameraConfig
from services.camera.png_folder.frames import FrameFolderError
from services.camera.registry import camera_entry
from tests.conftest import shared_data

CASTARD_INTRINSICS = "597.522,597.522,312.885,239.870"  # from the sequence's README (D415 colour stream)


def _castard():
    return shared_data("real_sequences", "castard_d415")


def _png(path, array) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)


def _small_folder(root, numbers=(3, 1, 12)):
    """``color_N.png`` + ``depth_N.png`` side by side, each pair's pixels saying its number."""
    for n in numbers:
        _png(root / f"color_{n:04d}.png", np.full((6, 8, 3), n, np.uint8))
        _png(root / f"depth_{n:04d}.png", np.full((6, 8), 100 * n, np.uint16))
    return root


def test_castard_frames_come_in_turn_order_pixel_identical_with_the_given_intrinsics():
    seq = _castard()
    cam = make_camera({"backend": "png_folder", "folder": str(seq), "intrinsics": CASTARD_INTRINSICS})
    assert isinstance(cam, PngFolderCamera)
    with cam:
        frames = [cam.capture() for _ in range(20)]
        with pytest.raises(EndOfReplay) as err:
            cam.capture()
    assert err.value.code == "end_of_replay" and err.value.detail["frames"] == 20
    assert [f.meta["png_folder"]["number"] for f in frames] == list(range(1, 21))  # numeric, not string order
    assert [f.seq for f in frames] == list(range(20))
    for k in (0, 9, 19):
        n = k + 1
        np.testing.assert_array_equal(frames[k].color, np.asarray(Image.open(seq / "rgb" / f"align_test{n}.png")
                                                                  .convert("RGB")))
        np.testing.assert_array_equal(frames[k].depth, np.asarray(Image.open(seq / "depth" /
                                                                             f"align_test_depth{n}.png")))
    K = frames[0].intrinsics
    assert (K.width, K.height) == (640, 480)
    assert (K.fx, K.fy, K.cx, K.cy) == (597.522, 597.522, 312.885, 239.870)
    assert frames[0].depth_scale == 0.001
    assert frames[0].meta[POSE_SOURCE_KEY] == "unknown" and np.array_equal(frames[0].T_base_camera, np.eye(4))


def test_side_by_side_layout_intrinsics_file_loop_and_given_pose(tmp_path):
    folder = _small_folder(tmp_path / "f")
    (folder / "intrinsics.json").write_text(json.dumps({"fx": 10.0, "fy": 11.0, "cx": 4.0, "cy": 3.0}))
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    with PngFolderCamera(PngFolderCameraConfig(folder=folder, depth_scale=0.0005, loop=True)) as cam:
        frames = [cam.capture(T) for _ in range(4)]
    assert [int(f.color[0, 0, 0]) for f in frames] == [1, 3, 12, 1]  # number order, then over again
    assert [int(f.depth[0, 0]) for f in frames] == [100, 300, 1200, 100]
    assert frames[0].intrinsics.fy == 11.0 and frames[0].depth_scale == 0.0005
    assert frames[0].meta[POSE_SOURCE_KEY] == "given" and np.array_equal(frames[0].T_base_camera, T)


def test_bad_folders_and_options_are_typed_errors(tmp_path):
    entry = camera_entry("png_folder")
    with pytest.raises(CameraConfigError):
        entry.config_from_options({})  # no folder
    with pytest.raises(CameraConfigError):
        entry.config_from_options({"folder": str(tmp_path), "depth_scale": "lots"})
    with pytest.raises(CameraConfigError):
        PngFolderCameraConfig(folder=tmp_path, depth_scale=0.0)
    folder = _small_folder(tmp_path / "f")
    cam = PngFolderCamera(PngFolderCameraConfig(folder=folder))  # no intrinsics given nor in the folder
    with pytest.raises(FrameFolderError) as err:
        cam.connect()
    assert err.value.code == "bad_intrinsics" and not cam.is_connected
    (folder / "depth_0012.png").unlink()
    with pytest.raises(FrameFolderError) as err:
        PngFolderCamera(PngFolderCameraConfig(folder=folder, intrinsics="5,5,4,3")).connect()
    assert err.value.code == "unpaired_frames" and err.value.detail["numbers"] == [12]
    with pytest.raises(FrameFolderError) as err:
        PngFolderCamera(PngFolderCameraConfig(folder=tmp_path / "none", intrinsics="5,5,4,3")).connect()
    assert err.value.code == "no_frames"


def test_the_camera_service_plays_a_png_folder_over_zenoh(service_group, tmp_path):
    """A real camera process with ``--backend png_folder``: captures answer the folder's frames in order,
    running out is a typed ``end_of_replay`` reply, and the service keeps running."""
    from common import keys
    from common.api import CaptureRequest
    from common.client import live_services, request_sync
    from common.errors import RemoteError
    from common.launcher import ProcessSpec
    from services.cli.main import main

    seq = _castard()
    folder = tmp_path / "two"
    for sub, name in (("rgb", "align_test"), ("depth", "align_test_depth")):
        (folder / sub).mkdir(parents=True)
        for n in (7, 8):
            (folder / sub / f"{name}{n}.png").symlink_to(seq / sub / f"{name}{n}.png")
    service_group.launch([ProcessSpec("services.camera", ["--backend", "png_folder", "--option", f"folder={folder}",
                                                          "--option", f"intrinsics={CASTARD_INTRINSICS}"],
                                      service="camera")], timeout=60)
    out = tmp_path / "cli"  # the first frame through ``objscan capture --backend png_folder``
    assert main(["capture", "--backend", "png_folder", "--connect", service_group.endpoint, "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["backend"] == "png_folder" and meta["png_folder"]["number"] == 7
    assert meta["intrinsics"]["fx"] == 597.522 and meta[POSE_SOURCE_KEY] == "unknown"
    np.testing.assert_array_equal(np.asarray(Image.open(out / "depth.png")),
                                  np.asarray(Image.open(seq / "depth" / "align_test_depth7.png")))
    s, key = service_group.session, keys.camera_capture(keys.DEFAULT_ROBOT)
    frame = request_sync(s, key, CaptureRequest(), timeout=30)
    assert frame.meta["png_folder"]["number"] == 8 and frame.seq == 1
    np.testing.assert_array_equal(frame.color, np.asarray(Image.open(seq / "rgb" / "align_test8.png").convert("RGB")))
    with pytest.raises(RemoteError) as err:
        request_sync(s, key, CaptureRequest(), timeout=30)
    assert err.value.code == "end_of_replay"
    assert "camera" in {name for name, _ in live_services(s)}  # still serving after the typed error

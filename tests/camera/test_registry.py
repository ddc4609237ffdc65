"""Backend names are spelled once: the camera and arm registries; cells, the CLI and compose use them."""

from __future__ import annotations

import re

import pytest

from common.backend_options import option_pair
from common.errors import ServiceStartError
from common.launcher import ProcessSpec
from services.arm.drivers.registry import BACKENDS as ARM_BACKENDS
from services.camera.base import Camera
from services.camera.errors import CameraConfigError
from services.camera.registry import BACKENDS, camera_entry, make_camera
from services.cell import CELLS, cell_specs, hardware_services, needs_twin
from tests.conftest import REPO


def test_every_camera_backend_resolves_to_its_folder_entry():
    assert set(BACKENDS) == {"sim", "realsense", "replay", "png_folder"}
    for name in BACKENDS:
        entry = camera_entry(name)
        assert entry.name == name and entry.config_class.backend == name and entry.description
    with pytest.raises(CameraConfigError) as err:
        camera_entry("webcam")
    assert err.value.code == "bad_config" and err.value.detail["known"] == sorted(BACKENDS)


def test_options_build_the_named_backend_through_the_interface(tmp_path):
    cam = make_camera(camera_entry("replay").config_from_options({"session": str(tmp_path)}))
    assert isinstance(cam, Camera) and cam.info()["backend"] == "replay" and not cam.pose_from_arm
    rs = camera_entry("realsense").config_from_options({"width": 848, "no_exposure_lock": True, "playback": "x.db3"})
    assert (rs.width, rs.lock_exposure, rs.playback_file) == (848, False, "x.db3")
    assert make_camera(rs).pose_from_arm  # the only backend stamped with the arm's belief
    assert option_pair("depth-scale=0.002") == ("depth_scale", "0.002")
    with pytest.raises(ValueError):
        option_pair("folder")


def test_cells_name_registry_backends_and_start_them():
    for cell, backends in CELLS.items():
        assert backends["camera"] in BACKENDS and backends["arm"] in ARM_BACKENDS, cell
    specs = {s.service: s.args for s in cell_specs(backend="real")}
    assert specs["camera"] == ["--backend", "realsense"] and specs["arm"] == ["--backend", "dynamixel"]
    assert specs["registration"] == []
    only = cell_specs(["camera"], backend={"camera": "png_folder"}, extra_args={"camera": ["--option", "folder=x"]})
    assert only[0].args == ["--backend", "png_folder", "--option", "folder=x"]
    assert needs_twin("sim") and not needs_twin("real") and not needs_twin({"camera": "replay"})
    assert hardware_services("sim") == ["sim", "arm", "camera"] and hardware_services("real") == ["arm", "camera"]
    assert hardware_services({"camera": "png_folder"}) == ["camera"]


def test_compose_files_start_registry_backends():
    files = [REPO / "docker-compose.yml", *sorted((REPO / "deploy").glob("docker-compose*.yml"))]
    seen = 0
    for path in files:
        for module, backend in re.findall(r'"services\.(camera|arm)",\s*"--backend",\s*"([^"]+)"', path.read_text()):
            assert backend in (BACKENDS if module == "camera" else ARM_BACKENDS), (path.name, module, backend)
            seen += 1
    assert seen >= 4  # sim and real cells, camera and arm


@pytest.mark.parametrize("source,corrected", [("given", True), ("sim", True), ("recorded", False), ("unknown", False)])
def test_the_service_corrects_live_poses_only(source, corrected):
    """One rule for every backend (it used to branch on the backend name): a hand-eye calibration corrects
    a pose given by the arm or stamped by the twin, never a recorded or an unknown one."""
    import numpy as np

    from common.geometry import make_transform
    from common.messages import RGBDFrame
    from services.calibration.file import HandEyeCalibration
    from services.camera.service import apply_hand_eye

    nominal = make_transform(np.eye(3), [0.04, 0.0, 0.05])
    cal = HandEyeCalibration(make_transform(np.eye(3), [0.042, 0.0, 0.05]), nominal)
    T = make_transform(np.eye(3), [0.3, 0.1, 0.4])
    frame = RGBDFrame(color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16), T_base_camera=T.copy(),
                      meta={"pose_source": source})
    out = apply_hand_eye(frame, cal, "he.json")
    assert np.allclose(out.T_base_camera[:3, 3], [0.302, 0.1, 0.4]) == corrected
    assert ("hand_eye" in out.meta) == corrected
    assert apply_hand_eye(frame, None, None) is frame  # no calibration: nothing to do


def test_camera_options_are_typed_by_the_backend_and_a_wrong_one_names_the_valid_keys():
    rs = camera_entry("realsense").options({"width": "848", "no_exposure_lock": "yes", "visual_preset": "none"})
    assert (rs.width, rs.no_exposure_lock, rs.visual_preset, rs.serial) == (848, True, None, None)
    with pytest.raises(CameraConfigError) as err:
        camera_entry("replay").options({"folder": "x"})
    assert err.value.code == "unknown_option" and err.value.detail["valid"] == ["session"]
    with pytest.raises(CameraConfigError) as err:
        camera_entry("png_folder").options({"depth_scale": "lots"})
    assert err.value.code == "bad_option" and err.value.detail == {
        "backend": "camera backend png_folder", "key": "depth_scale", "value": "lots", "type": "float"}


def test_the_camera_service_refuses_an_option_its_backend_does_not_have(service_group, tmp_path):
    with pytest.raises(ServiceStartError) as exc:
        service_group.launch([ProcessSpec("services.camera", ["--backend", "replay", "--option", f"folder={tmp_path}"],
                                          service="camera")], timeout=120)
    assert exc.value.code == "unknown_option", exc.value
    assert exc.value.detail["valid"] == ["session"]

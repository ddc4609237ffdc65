"""The plausibility bound: which scan corrections the arm's stated pose accuracy can explain."""

from __future__ import annotations

import numpy as np
import pytest

from common.geometry import make_transform, rotation_about_axis
from common.pose_accuracy import CONSERVATIVE, PoseAccuracy, PoseAccuracyError, session_pose_accuracy
from services.registration.static import StaticConfig
from services.registration.static.plausibility import correction_bound, implausibility


def test_the_bound_follows_the_arms_accuracy_with_a_floor():
    prior = make_transform(None, [0.15, 0.0, 0.02])  # 15 cm between the two cameras
    papras = StaticConfig().with_accuracy(PoseAccuracy(3.0, 1.0))
    b = correction_bound(prior, papras)
    # 5 sigma of two poses: sqrt(2) x 3 mm and the 1 degree swinging the 15 cm baseline; sqrt(2) x 1 degree
    assert b.m == pytest.approx(5 * np.sqrt(2 * 3e-3**2 + (np.radians(1.0) * np.linalg.norm(prior[:3, 3])) ** 2))
    assert b.deg == pytest.approx(5 * np.sqrt(2.0))
    perfect = correction_bound(prior, StaticConfig().with_accuracy(PoseAccuracy(0.0, 0.0)))
    assert (perfect.m, perfect.deg) == (pytest.approx(5e-3), pytest.approx(1.0))  # the floors
    assert StaticConfig().accuracy == CONSERVATIVE  # a session that states nothing


def test_a_quarter_turn_or_40_cm_is_implausible_for_any_stated_arm():
    prior = make_transform(None, [0.15, 0.0, 0.02])
    cfg = StaticConfig()
    R = rotation_about_axis([0.0, 0.0, 1.0], np.radians(90.0))
    assert "implausible" in implausibility(make_transform(R) @ prior, prior, cfg)
    assert "implausible" in implausibility(make_transform(None, [0.4, 0.0, 0.0]) @ prior, prior, cfg)
    small = make_transform(rotation_about_axis([0.0, 1.0, 0.0], np.radians(1.0)), [0.003, -0.002, 0.001])
    assert implausibility(small @ prior, prior, cfg) is None


def test_a_session_states_its_accuracy_or_gets_the_conservative_default():
    assert session_pose_accuracy({}) == (CONSERVATIVE, "default")
    stated = {"pose_accuracy": {"position_sigma_mm": 2.5, "orientation_sigma_deg": 0.8}}
    assert session_pose_accuracy(stated) == (PoseAccuracy(2.5, 0.8), "session")
    assert session_pose_accuracy({"config": stated}) == (PoseAccuracy(2.5, 0.8), "session")
    with pytest.raises(PoseAccuracyError) as exc:
        session_pose_accuracy({"pose_accuracy": {"position_sigma_mm": -1, "orientation_sigma_deg": 0.8}})
    assert exc.value.code == "bad_pose_accuracy"
    with pytest.raises(PoseAccuracyError):
        PoseAccuracy.from_dict({"position_sigma_mm": 1.0})


def test_papras_states_its_accuracy_and_a_bad_entry_names_the_key(tmp_path):
    from services.arm.drivers.dynamixel.robot_file import DEFAULT_ROBOT_CONFIG, read_robot_file, robot_pose_accuracy
    from services.arm.errors import RobotConfigError

    assert robot_pose_accuracy() == PoseAccuracy(3.0, 1.0)
    text = DEFAULT_ROBOT_CONFIG.read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("orientation_sigma_deg: 1.0", "orientation_sigma_deg: -2"))
    for read in (robot_pose_accuracy, read_robot_file):
        with pytest.raises(RobotConfigError) as exc:
            read(bad)
        assert exc.value.detail["key"] == "pose_accuracy.orientation_sigma_deg"
    silent = tmp_path / "silent.yaml"
    silent.write_text("\n".join(line for line in text.splitlines() if not line.startswith("pose_accuracy")))
    assert robot_pose_accuracy(silent) == CONSERVATIVE


def test_the_twins_profiles_state_the_accuracy_of_their_drawn_errors():
    from services.sim.profiles import get_profile

    ideal, realistic, robot = (get_profile(n).pose_accuracy() for n in ("ideal", "realistic", "robot-turned"))
    assert ideal == PoseAccuracy(0.0, 0.0)
    # realistic: per-scan 1-3 mm / 0.3-1 deg (RMS 2.08 mm / 0.68 deg), hand-eye 3 mm / 0.5 deg, joint jitter
    assert 3.5 < realistic.position_sigma_mm < 4.0 and 0.8 < realistic.orientation_sigma_deg < 0.9
    assert robot.position_sigma_mm < realistic.position_sigma_mm
    wider = get_profile("realistic", scan_pose_mm=(5.0, 10.0)).pose_accuracy()
    assert wider.position_sigma_mm > realistic.position_sigma_mm


def test_a_static_request_with_a_malformed_accuracy_is_a_typed_error():
    from common.api import StaticRequest
    from common.errors import WireError
    from common.messages import RGBDFrame

    frame = RGBDFrame(color=np.zeros((4, 4, 3), np.uint8), depth=np.zeros((4, 4), np.uint16), T_base_camera=np.eye(4))
    StaticRequest(frames=[frame], pose_accuracy={"position_sigma_mm": 3.0, "orientation_sigma_deg": 1.0}).validate()
    with pytest.raises(WireError) as exc:
        StaticRequest(frames=[frame], pose_accuracy={"position_sigma_mm": "far"}).validate()
    assert exc.value.code == "bad_value"

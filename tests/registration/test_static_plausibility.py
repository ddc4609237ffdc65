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

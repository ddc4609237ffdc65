"""The hand-eye calibration file: written by ``objscan calibrate hand-eye``, loaded by the camera service.

It holds the calibrated mount ``T_gripper_camera`` and the *nominal* mount the cell stamped frames with
while it was calibrated (the arm's URDF mount on a real cell; on the twin, the mount its hand-eye error
makes the robot believe). What a service applies is the difference, a fixed correction in the camera
frame: ``T_base_camera(calibrated) = T_base_camera(stamped) @ correction`` with
``correction = inv(T_gripper_camera_nominal) @ T_gripper_camera``. Expressing it that way means the file
works unchanged whether the stamp comes from the arm's kinematics (real cell) or from the twin.

JSON, one object, ``format`` 1; every matrix is validated on load (a broken file is a typed error, the
service refuses to start rather than stamp wrong poses).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ObjscanError
from common.geometry import as_rigid_transform, invert
from common.session_folder import atomic_write_json

FORMAT = 1
#: Environment variable naming the calibration file a service loads at start (compose mounts it).
ENV_VAR = "OBJSCAN_HAND_EYE"


class CalibrationError(ObjscanError):
    """A calibration file that is missing, unreadable or malformed."""

    code = "bad_calibration"


def _rigid(value: Any, name: str) -> np.ndarray:
    return as_rigid_transform(value, name, CalibrationError, class_code=True)


@dataclass
class HandEyeCalibration:
    """A solved hand-eye calibration and how it was obtained (``info``: method, residuals, views...)."""

    T_gripper_camera: np.ndarray
    T_gripper_camera_nominal: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.T_gripper_camera = _rigid(self.T_gripper_camera, "T_gripper_camera")
        self.T_gripper_camera_nominal = _rigid(self.T_gripper_camera_nominal, "T_gripper_camera_nominal")

    @property
    def correction(self) -> np.ndarray:
        """The fixed camera-frame correction applied to every stamped pose."""
        return invert(self.T_gripper_camera_nominal) @ self.T_gripper_camera

    def apply(self, T_base_camera: np.ndarray) -> np.ndarray:
        """The calibrated camera pose for a pose stamped with the nominal mount."""
        return np.asarray(T_base_camera, dtype=np.float64) @ self.correction

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "kind": "hand_eye", "T_gripper_camera": self.T_gripper_camera.tolist(),
                "T_gripper_camera_nominal": self.T_gripper_camera_nominal.tolist(),
                "correction": self.correction.tolist(), "info": self.info}

    def save(self, path: str | Path) -> Path:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(p, self.to_dict())
        return p


def load_calibration(path: str | Path) -> HandEyeCalibration:
    """Read and validate a calibration file (``CalibrationError``: ``calibration_not_found`` / ``bad_calibration``)."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise CalibrationError(f"hand-eye calibration file {p} does not exist (run 'objscan calibrate hand-eye')",
                               code="calibration_not_found", detail={"path": str(p)}) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"cannot read hand-eye calibration {p}: {exc}", detail={"path": str(p)}) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("kind") != "hand_eye":
        raise CalibrationError(f"{p} is not a hand-eye calibration file of format {FORMAT}",
                               detail={"path": str(p)})
    for key in ("T_gripper_camera", "T_gripper_camera_nominal"):
        if key not in doc:
            raise CalibrationError(f"{p} lacks {key}", detail={"path": str(p), "field": key})
    info = doc.get("info") if isinstance(doc.get("info"), dict) else {}
    return HandEyeCalibration(doc["T_gripper_camera"], doc["T_gripper_camera_nominal"], info)


def calibration_from_env(explicit: str | None = None) -> tuple[HandEyeCalibration | None, str | None]:
    """(calibration, path) from ``explicit`` or ``$OBJSCAN_HAND_EYE``; (None, None) when neither is set."""
    path = explicit or os.environ.get(ENV_VAR) or None
    if not path:
        return None, None
    return load_calibration(path), str(path)

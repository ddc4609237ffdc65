"""The robot configuration file (YAML) -> the fields of a ``DynamixelConfig``, validated with errors that name the key.

One file says which servo drives which joint and how: port, baud, per joint ID, model, zero offset,
direction, limits, profile velocity/acceleration (raw servo units, as PAPRAS's hardware.yaml), homing
offset, return delay; the gripper; the home posture, the shutdown policy and the settle check. The
PAPRAS default ships beside the URDF (``services/arm/robot/papras_dynamixel.yaml``). The key set is
closed: a misspelt key is an error, not a silently ignored line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from common.pose_accuracy import CONSERVATIVE, POSE_ACCURACY_KEY, PoseAccuracy, PoseAccuracyError
from services.arm.drivers.dynamixel.servo_config import GripperServoConfig, JointServoConfig
from services.arm.errors import RobotConfigError
from services.arm.robot import JOINT_NAMES

DEFAULT_ROBOT_CONFIG = Path(__file__).resolve().parents[2] / "robot" / "papras_dynamixel.yaml"

TOP_KEYS = {"port", "baudrate", "home", "shutdown", "settle_tolerance", "settle_timeout_s", "max_tracking_error",
            "profile_velocity_rad_s", "profile_acceleration_rad_s2", "joints", "gripper", "pose_accuracy"}
JOINT_KEYS = {"id": "dxl_id", "model": "model", "offset": "offset_rad", "direction": "direction", "limits": "limits",
              "profile_velocity": "profile_velocity", "profile_acceleration": "profile_acceleration",
              "homing_offset": "homing_offset", "return_delay_time": "return_delay_time"}
GRIPPER_KEYS = {"id": "dxl_id", "model": "model", "profile_velocity": "profile_velocity",
                "profile_acceleration": "profile_acceleration", "return_delay_time": "return_delay_time",
                "ticks_open": "ticks_open", "ticks_closed": "ticks_closed", "stroke_m": "stroke_m"}


def _mapping(key: str, value: Any) -> dict:
    if not isinstance(value, dict):
        raise RobotConfigError(f"{key}: expected a mapping", detail={"key": key, "got": type(value).__name__})
    return value


def _unknown(key: str, given: dict, allowed: set[str] | dict) -> None:
    extra = sorted(set(given) - set(allowed))
    if extra:
        raise RobotConfigError(f"{key}: unknown key(s) {', '.join(map(str, extra))}",
                               detail={"key": key, "unknown": extra, "allowed": sorted(allowed)})


def _servo_kwargs(name: str, entry: Any, keys: dict[str, str]) -> dict:
    entry = _mapping(name, entry)
    _unknown(name, entry, keys)
    if "id" not in entry:
        raise RobotConfigError(f"{name}: 'id' is required", detail={"key": f"{name}.id"})
    kw = {keys[k]: v for k, v in entry.items()}
    if isinstance(kw.get("limits"), list):
        if len(kw["limits"]) != 2:
            raise RobotConfigError(f"{name}.limits: expected [lower, upper]", detail={"key": f"{name}.limits"})
        kw["limits"] = tuple(kw["limits"])
    return {**kw, "name": name}


def robot_fields_from_dict(data: Any, source: str = "<dict>") -> dict[str, Any]:
    """The keyword arguments of a ``DynamixelConfig`` from parsed YAML (servo entries validated here)."""
    data = _mapping(source, data)
    _unknown(source, data, TOP_KEYS)
    joints_in = _mapping("joints", data.get("joints"))
    missing = [n for n in JOINT_NAMES if n not in joints_in]
    _unknown("joints", joints_in, set(JOINT_NAMES))
    if missing:
        raise RobotConfigError(f"joints: missing {', '.join(missing)}", detail={"key": "joints", "missing": missing})
    try:
        joints = [JointServoConfig(**_servo_kwargs(n, joints_in[n], JOINT_KEYS)) for n in JOINT_NAMES]
        gripper = None
        if data.get("gripper") is not None:
            g = _mapping("gripper", data["gripper"])
            if len(g) != 1:
                raise RobotConfigError("gripper: exactly one gripper servo", detail={"key": "gripper"})
            (gname, gentry), = g.items()
            gripper = GripperServoConfig(**_servo_kwargs(str(gname), gentry, GRIPPER_KEYS))
    except RobotConfigError as exc:
        exc.detail.setdefault("file", source)
        raise
    except (TypeError, ValueError) as exc:
        raise RobotConfigError(f"{source}: {exc}", detail={"file": source}) from exc
    if data.get(POSE_ACCURACY_KEY) is not None:  # read by ``robot_pose_accuracy``; validated here as well
        try:
            PoseAccuracy.from_dict(data[POSE_ACCURACY_KEY])
        except PoseAccuracyError as exc:
            raise RobotConfigError(f"{source}: {exc.message}", detail={**exc.detail, "file": source}) from exc
    fields: dict[str, Any] = {k: data[k] for k in ("port", "baudrate", "shutdown", "settle_tolerance",
                                                    "settle_timeout_s", "max_tracking_error") if k in data}
    if "home" in data:
        fields["home"] = tuple(data["home"]) if isinstance(data["home"], list) else data["home"]
    if "profile_velocity_rad_s" in data:
        fields["profile_velocity"] = data["profile_velocity_rad_s"]
    if "profile_acceleration_rad_s2" in data:
        fields["profile_acceleration"] = data["profile_acceleration_rad_s2"]
    return {"joints": joints, "gripper": gripper, **fields}


def robot_pose_accuracy(path: str | Path | None = None) -> PoseAccuracy:
    """The arm's camera pose accuracy the robot configuration states (``pose_accuracy``), or the
    conservative default when the file states none; a malformed entry is a ``RobotConfigError``."""
    path = Path(path) if path else DEFAULT_ROBOT_CONFIG
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise RobotConfigError(f"cannot read the robot configuration {path}: {exc}",
                               detail={"file": str(path)}) from exc
    entry = _mapping(str(path), data).get(POSE_ACCURACY_KEY)
    if entry is None:
        return CONSERVATIVE
    try:
        return PoseAccuracy.from_dict(entry)
    except PoseAccuracyError as exc:
        raise RobotConfigError(f"{path}: {exc.message}", detail={**exc.detail, "file": str(path)}) from exc


def read_robot_file(path: str | Path | None = None, **overrides: Any) -> dict[str, Any]:
    """Read a robot configuration file (default: the PAPRAS one shipped with the arm service) into fields.

    ``overrides`` (e.g. ``port=...`` from a command line) replace top-level keys after reading."""
    path = Path(path) if path else DEFAULT_ROBOT_CONFIG
    try:
        text = path.read_text()
    except OSError as exc:
        raise RobotConfigError(f"cannot read the robot configuration {path}: {exc.strerror}",
                               detail={"file": str(path)}) from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise RobotConfigError(f"{path} is not valid YAML: {exc}", detail={"file": str(path)}) from exc
    data = _mapping(str(path), data)
    data.update({k: v for k, v in overrides.items() if v is not None})
    return robot_fields_from_dict(data, str(path))

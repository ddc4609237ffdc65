"""The robot configuration file (YAML) -> a validated ``DynamixelConfig``: the parser (``robot_file.py``)
joined to the bus configuration (``config.py``), which also takes its defaults from the shipped PAPRAS file.

One file says which servo drives which joint and how: port, baud, per joint ID, model, zero offset,
direction, limits, profile velocity/acceleration (raw servo units, as PAPRAS's hardware.yaml), homing
offset, return delay; the gripper; the home posture, the shutdown policy and the settle check (docs/arm.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from services.arm.drivers.dynamixel.config import DynamixelConfig
from services.arm.drivers.dynamixel.robot_file import DEFAULT_ROBOT_CONFIG, read_robot_file, robot_fields_from_dict
from services.arm.errors import RobotConfigError

__all__ = ["DEFAULT_ROBOT_CONFIG", "load_robot_config", "robot_config_from_dict"]


def _build(fields: dict[str, Any], source: str) -> DynamixelConfig:
    try:
        return DynamixelConfig(**fields)
    except RobotConfigError as exc:
        exc.detail.setdefault("file", source)
        raise
    except (TypeError, ValueError) as exc:
        raise RobotConfigError(f"{source}: {exc}", detail={"file": source}) from exc


def robot_config_from_dict(data: Any, source: str = "<dict>") -> DynamixelConfig:
    """Build and validate a ``DynamixelConfig`` from parsed YAML."""
    return _build(robot_fields_from_dict(data, source), source)


def load_robot_config(path: str | Path | None = None, **overrides: Any) -> DynamixelConfig:
    """Read a robot configuration file (default: the PAPRAS one shipped with the arm service)."""
    return _build(read_robot_file(path, **overrides), str(Path(path) if path else DEFAULT_ROBOT_CONFIG))

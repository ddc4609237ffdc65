"""Replay backend: frames from a recorded session folder.

Options: ``session`` (the session folder). Its frames keep their recorded poses.
"""

from __future__ import annotations

from typing import Any

from services.camera.registry import CameraContext, CameraEntry
from services.camera.replay.camera import ReplayCamera, list_recorded_scans
from services.camera.replay.config import ReplayCameraConfig


def _config(options: dict[str, Any]) -> ReplayCameraConfig:
    return ReplayCameraConfig(session_dir=options.get("session") or "")


def _factory(config: ReplayCameraConfig, ctx: CameraContext) -> ReplayCamera:
    return ReplayCamera(config)


CAMERA = CameraEntry("replay", ReplayCameraConfig, _config, _factory,
                     description="the frames of a recorded session folder, in order",
                     options={"session": "the session folder to serve frames from"})

__all__ = ["CAMERA", "ReplayCamera", "ReplayCameraConfig", "list_recorded_scans"]

"""Replay backend: frames from a recorded session folder.

Options: ``session`` (the session folder). Its frames keep their recorded poses.
"""

from __future__ import annotations

from services.camera.registry import CameraContext, CameraEntry
from services.camera.replay.camera import ReplayCamera, list_recorded_scans
from services.camera.replay.config import ReplayCameraConfig, ReplayCameraOptions


def _config(options: ReplayCameraOptions) -> ReplayCameraConfig:
    return ReplayCameraConfig(session_dir=options.session)


def _factory(config: ReplayCameraConfig, ctx: CameraContext) -> ReplayCamera:
    return ReplayCamera(config)


CAMERA = CameraEntry("replay", ReplayCameraConfig, ReplayCameraOptions, _config, _factory,
                     description="the frames of a recorded session folder, in order")

__all__ = ["CAMERA", "ReplayCamera", "ReplayCameraConfig", "list_recorded_scans"]

"""Replay backend: frames from a recorded session folder."""

from services.camera.replay.camera import ReplayCamera, list_recorded_scans
from services.camera.replay.config import ReplayCameraConfig

__all__ = ["ReplayCamera", "ReplayCameraConfig", "list_recorded_scans"]

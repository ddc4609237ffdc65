"""RealSense D435 backend (pyrealsense2): live camera, .db3 playback, and a software D435 for tests."""

from services.camera.realsense.camera import RealSenseCamera
from services.camera.realsense.config import RealSenseCameraConfig

__all__ = ["RealSenseCamera", "RealSenseCameraConfig"]

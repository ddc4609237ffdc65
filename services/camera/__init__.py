"""The camera service's backends: one ``Camera`` interface, ``sim`` | ``realsense`` | ``replay``.

``make_camera(config)`` builds one; see docs/camera.md.
"""

from services.camera.base import Camera, CameraConfig, check_frame, check_pose
from services.camera.errors import (
    BadFrameError,
    BadPoseError,
    CameraConfigError,
    CameraError,
    CaptureTimeout,
    EndOfReplay,
    NoDeviceError,
    NotConnectedError,
    ReplayDataError,
)
from services.camera.factory import config_from_dict, make_camera
from services.camera.realsense.config import RealSenseCameraConfig
from services.camera.replay.config import ReplayCameraConfig
from services.camera.sim.config import SimCameraConfig

__all__ = [
    "BadFrameError", "BadPoseError", "Camera", "CameraConfig", "CameraConfigError", "CameraError",
    "CaptureTimeout", "EndOfReplay", "NoDeviceError", "NotConnectedError", "RealSenseCameraConfig",
    "ReplayCameraConfig", "ReplayDataError", "SimCameraConfig", "check_frame", "check_pose",
    "config_from_dict", "make_camera",
]

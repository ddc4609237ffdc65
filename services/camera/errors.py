"""Typed camera errors with stable codes.

The camera service turns these into ``Error`` replies, so a caller (the orchestrator, the CLI) can branch
on ``code`` without parsing messages: ``no_device`` means plug a camera in, ``end_of_replay`` means a
recorded session has been served completely, ``timeout`` means the device stopped delivering frames.
"""

from __future__ import annotations

from common.errors import ObjscanError


class CameraError(ObjscanError):
    """Any failure of a camera backend."""

    code = "camera_error"


class CameraConfigError(CameraError):
    """The configuration asks for something impossible (unknown backend, bad size, unknown key)."""

    code = "bad_config"


class NoDeviceError(CameraError):
    """No camera is attached, or not the one whose serial number was asked for."""

    code = "no_device"


class NotConnectedError(CameraError):
    """``capture`` was called before ``connect`` (or after ``disconnect``)."""

    code = "not_connected"


class CaptureTimeout(CameraError):
    """The device (or the sim) did not deliver a frame in time."""

    code = "timeout"


class EndOfReplay(CameraError):
    """Every recorded frame has been served (replay folder or .db3 playback without looping)."""

    code = "end_of_replay"


class ReplayDataError(CameraError):
    """A recorded session folder or playback file is missing, empty or corrupt."""

    code = "bad_replay"


class BadFrameError(CameraError):
    """A backend produced, or was handed, a frame that is not a valid aligned RGB-D frame."""

    code = "bad_frame"


class BadPoseError(CameraError):
    """The camera pose passed to ``capture`` is not a finite 4x4 rigid transform."""

    code = "bad_pose"

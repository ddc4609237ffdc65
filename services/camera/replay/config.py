"""Configuration of the replay backend."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from common.backend_options import option
from services.camera.base import CameraConfig
from services.camera.errors import CameraConfigError


@dataclass(frozen=True)
class ReplayCameraOptions:
    """``--option session=DIR`` on the camera service."""

    session: str = option("", "the session folder to serve frames from")


@dataclass
class ReplayCameraConfig(CameraConfig):
    """Serve the frames of a recorded session folder (docs/session-folder.md) in order.

    ``loop``: start over after the last frame instead of raising ``end_of_replay``.
    """

    backend: ClassVar[str] = "replay"

    session_dir: str | Path = ""
    loop: bool = False

    def __post_init__(self) -> None:
        if not str(self.session_dir):
            raise CameraConfigError("the replay backend needs session_dir")
        self.session_dir = Path(self.session_dir)

"""Configuration of the PNG-folder backend."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from common.backend_options import option
from services.camera.base import CameraConfig
from services.camera.errors import CameraConfigError


@dataclass(frozen=True)
class PngFolderOptions:
    """``--option KEY=VALUE`` on the camera service."""

    folder: str = option("", "the folder of colour/depth PNG frames")
    intrinsics: str = option("", "fx,fy,cx,cy or a JSON file (default: the folder's intrinsics.json)")
    depth_scale: float = option(0.001, "metres per depth unit")
    loop: bool = option(False, "start over at the end of the folder")


@dataclass
class PngFolderCameraConfig(CameraConfig):
    """Play a folder of colour/depth PNG frames (layouts: ``png_folder/frames.py``) in capture order.

    - ``folder``: the folder (e.g. ``../shared/data/real_sequences/castard_d415``).
    - ``intrinsics``: the colour camera's ``fx,fy,cx,cy`` in pixels, or a JSON file with those keys; empty:
      ``intrinsics.json`` in the folder.
    - ``depth_scale``: metres per depth unit (0.001: millimetre PNGs, as librealsense writes them).
    - ``loop``: start over after the last frame instead of raising ``end_of_replay``.
    """

    backend: ClassVar[str] = "png_folder"

    folder: str | Path = ""
    intrinsics: str = ""
    depth_scale: float = 0.001
    loop: bool = False

    def __post_init__(self) -> None:
        if not str(self.folder):
            raise CameraConfigError("the png_folder backend needs folder")
        self.folder = Path(self.folder)
        if not (isinstance(self.depth_scale, (int, float)) and not isinstance(self.depth_scale, bool)
                and np.isfinite(self.depth_scale) and self.depth_scale > 0):
            raise CameraConfigError("depth_scale must be a positive number", detail={"depth_scale": self.depth_scale})

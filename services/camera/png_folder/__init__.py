"""PNG-folder backend: a folder of colour/depth PNG frames played as a camera (the worked example of
docs/extending.md).

Options (``--option KEY=VALUE`` on the camera service): ``folder``, ``intrinsics`` (``fx,fy,cx,cy`` or a
JSON file; default: the folder's ``intrinsics.json``), ``depth_scale`` (default 0.001), ``loop``.
"""

from __future__ import annotations

from typing import Any

from services.camera.errors import CameraConfigError
from services.camera.png_folder.camera import PngFolderCamera
from services.camera.png_folder.config import PngFolderCameraConfig
from services.camera.registry import CameraContext, CameraEntry


def _config(options: dict[str, Any]) -> PngFolderCameraConfig:
    try:
        depth_scale = float(options.get("depth_scale", 0.001))
    except (TypeError, ValueError):
        raise CameraConfigError("depth_scale must be a number",
                                detail={"depth_scale": options["depth_scale"]}) from None
    return PngFolderCameraConfig(folder=options.get("folder") or "", intrinsics=options.get("intrinsics") or "",
                                 depth_scale=depth_scale,
                                 loop=str(options.get("loop", "")).lower() in ("1", "true", "yes"))


def _factory(config: PngFolderCameraConfig, ctx: CameraContext) -> PngFolderCamera:
    return PngFolderCamera(config)


CAMERA = CameraEntry("png_folder", PngFolderCameraConfig, _config, _factory,
                     description="a folder of colour/depth PNG frames with given intrinsics",
                     options={"folder": "the folder of frames", "intrinsics": "fx,fy,cx,cy or a JSON file",
                              "depth_scale": "metres per depth unit (0.001)", "loop": "start over at the end"})

__all__ = ["CAMERA", "PngFolderCamera", "PngFolderCameraConfig"]

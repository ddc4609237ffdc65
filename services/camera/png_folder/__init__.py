"""PNG-folder backend: a folder of colour/depth PNG frames played as a camera (the worked example of
docs/extending.md).

Options (``--option KEY=VALUE`` on the camera service): ``folder``, ``intrinsics`` (``fx,fy,cx,cy`` or a
JSON file; default: the folder's ``intrinsics.json``), ``depth_scale`` (default 0.001), ``loop``.
"""

from __future__ import annotations

from services.camera.png_folder.camera import PngFolderCamera
from services.camera.png_folder.config import PngFolderCameraConfig, PngFolderOptions
from services.camera.registry import CameraContext, CameraEntry


def _config(options: PngFolderOptions) -> PngFolderCameraConfig:
    return PngFolderCameraConfig(folder=options.folder, intrinsics=options.intrinsics,
                                 depth_scale=options.depth_scale, loop=options.loop)


def _factory(config: PngFolderCameraConfig, ctx: CameraContext) -> PngFolderCamera:
    return PngFolderCamera(config)


CAMERA = CameraEntry("png_folder", PngFolderCameraConfig, PngFolderOptions, _config, _factory,
                     description="a folder of colour/depth PNG frames with given intrinsics")

__all__ = ["CAMERA", "PngFolderCamera", "PngFolderCameraConfig"]

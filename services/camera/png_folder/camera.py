"""The PNG-folder backend: the frames of a fixed camera saved as colour/depth PNG pairs, played in order.

A stand-in for a camera when only images exist (a public RGB-D sequence, frames saved by another tool):
each capture serves the next pair with the given intrinsics. The folder holds no pose, so a frame carries
the pose passed to ``capture`` or, with none (the service passes none), the identity marked ``unknown``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from common.messages import Intrinsics, RGBDFrame
from services.camera.base import Camera, stamp_pose
from services.camera.errors import EndOfReplay
from services.camera.png_folder.config import PngFolderCameraConfig
from services.camera.png_folder.frames import folder_intrinsics, pair_images, parse_intrinsics, read_pair


class PngFolderCamera(Camera):
    """Pairs of a PNG folder, in number order; ``end_of_replay`` after the last unless ``loop``."""

    config: PngFolderCameraConfig

    def __init__(self, config: PngFolderCameraConfig):
        super().__init__(config)
        self._pairs: list[tuple[int, Path, Path]] = []
        self._intrinsics: Intrinsics | None = None
        self._next = 0

    def _open(self) -> None:
        folder = Path(self.config.folder)
        given = parse_intrinsics(self.config.intrinsics) if self.config.intrinsics else None
        self._intrinsics = folder_intrinsics(folder, given)
        self._pairs = pair_images(folder)
        self._next = 0

    def _grab(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        if self._next >= len(self._pairs):
            if not self.config.loop:
                n = len(self._pairs)
                raise EndOfReplay(f"all {n} frames of {self.config.folder} were served", detail={"frames": n})
            self._next = 0
        n, cpath, dpath = self._pairs[self._next]
        assert self._intrinsics is not None
        frame = read_pair(n, cpath, dpath, self._intrinsics, self.config.depth_scale)
        frame.T_base_camera = stamp_pose(frame.meta, T_base_camera)
        frame.seq = self._next_seq()
        frame.meta["png_folder"] = {"number": n, "index": self._next}
        self._next += 1
        return frame

    def _close(self) -> None:
        self._next = 0

    def _info(self) -> dict[str, Any]:
        return {"folder": str(self.config.folder), "frames": len(self._pairs), "next_index": self._next,
                "loop": self.config.loop}

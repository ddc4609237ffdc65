"""The replay backend: serve a recorded session folder's scans, view by view, scan by scan.

A replay must reproduce the recorded session, so every frame keeps what was recorded (pose, stamp, seq,
intrinsics, ground truth) and the pose the caller passes in is ignored (``meta['pose_source'] =
'recorded'``). Only complete scans (those with a ``meta.json``) are served; a file that is missing or
corrupt when its turn comes raises ``bad_replay`` naming it, and running out raises ``end_of_replay``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from common.messages import RGBDFrame
from common.session_folder import SessionFolderError, read_session, scan_dir
from common.session_folder import read_scan_dir as _read_scan_dir
from services.camera.base import POSE_SOURCE_KEY, Camera, check_frame
from services.camera.errors import BadFrameError, EndOfReplay, ReplayDataError
from services.camera.replay.config import ReplayCameraConfig


def list_recorded_scans(session_dir: Path) -> list[tuple[int, int]]:
    """(view, scan) of every complete scan of a session folder, in capture order (view, then scan)."""
    try:
        info = read_session(session_dir)
        order = [(int(v["index"]), scan) for v in info.views for scan in info.scans(int(v["index"]))]
    except SessionFolderError as exc:
        raise ReplayDataError(f"cannot replay {session_dir}: {exc.message}",
                              detail={"session_dir": str(session_dir)}) from None
    except (KeyError, TypeError, ValueError) as exc:
        raise ReplayDataError(f"cannot replay {session_dir}: session.json lists a view without a valid index "
                              f"({exc!r})", detail={"session_dir": str(session_dir)}) from None
    if not order:
        raise ReplayDataError(f"session folder {session_dir} holds no complete scan "
                              "(no view_KK/scan_J/meta.json)", detail={"session_dir": str(session_dir)})
    return order


class ReplayCamera(Camera):
    """Frames of a recorded session folder, in order; ``end_of_replay`` after the last unless ``loop``."""

    config: ReplayCameraConfig

    def __init__(self, config: ReplayCameraConfig):
        super().__init__(config)
        self._order: list[tuple[int, int]] = []
        self._next = 0

    @property
    def remaining(self) -> int:
        """Frames left before ``end_of_replay`` (0 once exhausted; meaningless with ``loop``)."""
        return max(0, len(self._order) - self._next)

    def _open(self) -> None:
        self._order = list_recorded_scans(Path(self.config.session_dir))
        self._next = 0

    def _grab(self, T_base_camera: np.ndarray | None) -> RGBDFrame:
        if self._next >= len(self._order):
            if not self.config.loop:
                n = len(self._order)
                raise EndOfReplay(f"all {n} recorded frames of {self.config.session_dir} were served",
                                  detail={"frames": n})
            self._next = 0
        view, scan = self._order[self._next]
        d = scan_dir(Path(self.config.session_dir), view, scan)
        try:
            frame = _read_scan_dir(d)
            check_frame(frame)
        except (SessionFolderError, BadFrameError) as exc:
            raise ReplayDataError(f"recorded scan {d} cannot be replayed: {exc.message}",
                                  detail={"view": view, "scan": scan, "path": str(d)}) from None
        self._next += 1
        frame.meta = dict(frame.meta or {})
        frame.meta[POSE_SOURCE_KEY] = "recorded"
        frame.meta["replay"] = {"view": view, "scan": scan, "index": self._next - 1}
        if T_base_camera is not None:
            frame.meta["requested_pose_ignored"] = True
        return frame

    def _close(self) -> None:
        self._next = 0

    def _info(self) -> dict[str, Any]:
        return {"session_dir": str(self.config.session_dir), "recorded_frames": len(self._order),
                "next_index": self._next, "loop": self.config.loop}

"""Reading a fixed-camera sequence: a folder of color + depth images, or a RealSense recording.

A folder is read as the ``png_folder`` camera reads it (``services/camera/png_folder/frames.py``: pairing
by the last number in the names, in that number's order = the turn order); intrinsics come from the caller
(or ``intrinsics.json`` in the folder); a recording carries its own.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from common.messages import Intrinsics, RGBDFrame
from services.camera.png_folder import frames
from services.camera.png_folder.frames import FrameFolderError
from services.importer.errors import ImportError_

RECORDING_SUFFIXES = (".bag", ".db3")


@contextmanager
def _as_import_error() -> Iterator[None]:
    """The folder reader is the png_folder camera's: its errors keep their code as ``ImportError_``."""
    try:
        yield
    except FrameFolderError as exc:
        raise ImportError_(exc.message, code=exc.code, detail=exc.detail) from None


def parse_intrinsics(text: str, width: int = 0, height: int = 0) -> Intrinsics:
    """``fx,fy,cx,cy`` (pixels) or a JSON file with those keys (and optionally width/height)."""
    with _as_import_error():
        return frames.parse_intrinsics(text, width, height)


def pair_images(folder: Path) -> list[tuple[int, Path, Path]]:
    """(number, color, depth) for every numbered pair, in number order."""
    with _as_import_error():
        return frames.pair_images(folder)


def read_folder(folder: Path, intrinsics: Intrinsics | None, depth_scale: float) -> Iterator[RGBDFrame]:
    """Frames of an image folder, in turn order; the base pose is left as identity (set later)."""
    with _as_import_error():
        intrinsics = frames.folder_intrinsics(folder, intrinsics)
    if not (depth_scale > 0 and np.isfinite(depth_scale)):
        raise ImportError_("depth_scale must be positive", code="bad_value", detail={"depth_scale": depth_scale})
    for n, cpath, dpath in pair_images(folder):
        with _as_import_error():
            frame = frames.read_pair(n, cpath, dpath, intrinsics, depth_scale)
        yield frame


def read_recording(path: Path) -> Iterator[RGBDFrame]:
    """Every frame of a RealSense ``.bag``/``.db3`` recording, depth aligned to color, in recorded order."""
    from services.camera.errors import EndOfReplay, ReplayDataError
    from services.camera.realsense.camera import RealSenseCamera
    from services.camera.realsense.config import RealSenseCameraConfig

    cam = RealSenseCamera(RealSenseCameraConfig(playback_file=str(path), warmup_frames=0))
    try:
        cam.connect()
        k = 0
        while True:
            try:
                frame = cam.capture(None)
            except EndOfReplay:
                break
            frame.seq = k
            frame.T_base_camera = np.eye(4)  # the camera's own frame until the table gives base (base_frame.py)
            # the backend marks a frame captured without a pose as unusable (pose_source "unknown"); here no
            # pose is expected: the fixed camera's pose comes from the table, like a folder's frames
            frame.meta = {k_: v for k_, v in (frame.meta or {}).items() if k_ != "pose_source"}
            yield frame
            k += 1
    except ReplayDataError as exc:
        raise ImportError_(f"cannot read the recording {path}: {exc.message}", code="bad_recording",
                           detail=exc.detail) from None
    finally:
        cam.disconnect()


def read_frames(source: str | Path, intrinsics: Intrinsics | None = None, depth_scale: float = 0.001,
                every: int = 1) -> list[RGBDFrame]:
    """All frames of ``source`` (folder or recording), keeping one in ``every``."""
    src = Path(source)
    if src.is_dir():
        frames = list(read_folder(src, intrinsics, depth_scale))
    elif src.is_file() and src.suffix.lower() in RECORDING_SUFFIXES:
        frames = list(read_recording(src))
    else:
        raise ImportError_(f"{src} is neither a folder of RGB-D images nor a .bag/.db3 recording",
                           code="bad_source")
    if every < 1:
        raise ImportError_("every must be at least 1", code="bad_value")
    frames = frames[::every]
    if len(frames) < 3:
        raise ImportError_(f"a sequence needs at least 3 frames, found {len(frames)}", code="no_frames")
    return frames

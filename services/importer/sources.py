"""Reading a fixed-camera sequence: a folder of color + depth images, or a RealSense recording.

A folder is read as the ``png_folder`` camera reads it (``services/camera/png_folder/frames.py``: pairing
by the last number in the names, in that number's order = the turn order); intrinsics come from the caller
(or ``intrinsics.json`` in the folder); a recording carries its own.

Frames are streamed: ``--every`` is applied while reading (a folder decodes only the pairs it keeps, a
recording reads past the others without aligning or copying them), and at most ``max_frames`` are kept, so a long
recording or folder never sits in memory whole (``too_many_frames`` says which ``--every`` would fit).

A folder need not be perfect: an image without its partner (a depth stream recorded longer than the colour),
an unreadable image, a depth image of another size than its colour image, are skipped with a one-line warning
each (logger ``objscan.import``) and listed in ``skipped``; then one line gives the count. Only a folder with
fewer than ``MIN_FRAMES`` usable frames is refused (``no_frames``, with the count).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from common.messages import Intrinsics, RGBDFrame
from services.camera.png_folder import frames
from services.camera.png_folder.frames import FrameFolderError
from services.importer.errors import ImportError_

RECORDING_SUFFIXES = (".bag", ".db3")
MIN_FRAMES = 3  # a sequence with fewer usable frames has no turn to tell
log = logging.getLogger("objscan.import")


def skip(skipped: list[dict] | None, frame: int, code: str, message: str, stage: str = "read") -> None:
    """Record a frame left out (``skipped``) and say so in one warning line."""
    entry = {"stage": stage, "frame": int(frame), "code": code, "message": message}
    if skipped is not None:
        skipped.append(entry)
    log.warning("frame %d skipped (%s): %s", frame, code, " ".join(message.split()))


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


def pair_images(folder: Path, skipped: list[dict] | None = None) -> list[tuple[int, Path, Path]]:
    """(number, color, depth) for every numbered pair, in number order; an image without a partner is
    skipped (``skip``), not a refusal."""
    with _as_import_error():
        pairs, lonely = frames.match_images(folder)
    for n, has in lonely:
        missing = "depth" if has == "color" else "color"
        skip(skipped, n, "unpaired_frames", f"{has} image without its {missing} image")
    return pairs


#: Frames an import keeps at most (after ``every``): about 1.5 MB each at 640 x 480, all held until the table
#: and the turns are found. One a degree over a full turn; a longer sequence needs ``--every``.
MAX_FRAMES = 360


def _too_many(kept_at_least: int, every: int, max_frames: int, total: int | None = None) -> ImportError_:
    detail: dict[str, object] = {"kept_at_least": kept_at_least, "every": every, "max_frames": max_frames}
    hint = ""
    if total is not None:
        detail["frames"] = total
        need = -(-total // max_frames)
        detail["every_needed"] = need
        hint = f" (the source has {total} frames: --every {need} or more)"
    return ImportError_(f"keeping one frame in {every} gives more than {max_frames} frames{hint}; keep fewer "
                        "with --every", code="too_many_frames", detail=detail)


def read_folder(folder: Path, intrinsics: Intrinsics | None, depth_scale: float, every: int = 1,
                max_frames: int | None = None, skipped: list[dict] | None = None) -> Iterator[RGBDFrame]:
    """The kept frames (one pair in ``every``) of an image folder, in turn order, decoded one at a time;
    the base pose is left as identity (set later). More than ``max_frames`` kept is refused before any
    image is decoded. Unpaired and unreadable images are skipped (``skip``)."""
    with _as_import_error():
        intrinsics = frames.folder_intrinsics(folder, intrinsics)
    if not (depth_scale > 0 and np.isfinite(depth_scale)):
        raise ImportError_("depth_scale must be positive", code="bad_value", detail={"depth_scale": depth_scale})
    pairs = pair_images(folder, skipped)
    kept = pairs[::every]
    if max_frames is not None and len(kept) > max_frames:
        raise _too_many(len(kept), every, max_frames, total=len(pairs))
    for n, cpath, dpath in kept:
        try:
            frame = frames.read_pair(n, cpath, dpath, intrinsics, depth_scale)
        except FrameFolderError as exc:
            skip(skipped, n, exc.code, exc.message)
            continue
        yield frame


def read_recording(path: Path, every: int = 1) -> Iterator[RGBDFrame]:
    """One frame in ``every`` of a RealSense ``.bag``/``.db3`` recording, depth aligned to color, in recorded
    order (``seq`` = the frame's index in the recording); the others are read past, never aligned or copied."""
    from services.camera.errors import EndOfReplay, ReplayDataError
    from services.camera.realsense.camera import RealSenseCamera
    from services.camera.realsense.config import RealSenseCameraConfig

    cam = RealSenseCamera(RealSenseCameraConfig(playback_file=str(path), warmup_frames=0))
    try:
        cam.connect()
        k = 0
        while True:
            try:
                if k % every:
                    cam.skip_frame()
                    k += 1
                    continue
                frame = cam.capture(None)
            except EndOfReplay:
                break
            frame.seq = k
            frame.T_base_camera = np.eye(4)  # the camera's own frame until the table gives base (base_frame.py)
            # the backend marks a frame captured without a pose as unusable (pose_source "unknown"); here no
            # pose is expected: the fixed camera's pose comes from the table, like a folder's frames
            frame.meta = {k_: v for k_, v in (frame.meta or {}).items() if k_ != "pose_source"}
            yield frame
            del frame  # the caller keeps it or not: not this reader
            k += 1
    except ReplayDataError as exc:
        raise ImportError_(f"cannot read the recording {path}: {exc.message}", code="bad_recording",
                           detail=exc.detail) from None
    finally:
        cam.disconnect()


def iter_frames(source: str | Path, intrinsics: Intrinsics | None = None, depth_scale: float = 0.001,
                every: int = 1, max_frames: int | None = MAX_FRAMES,
                skipped: list[dict] | None = None) -> Iterator[RGBDFrame]:
    """The frames of ``source`` (folder or recording) to keep, one in ``every``, as they are read: a skipped
    frame is never decoded (folder) or never aligned or copied (recording), so no frame beyond those kept
    is held."""
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ImportError_("every must be at least 1", code="bad_value", detail={"every": repr(every)[:40]})
    src = Path(source)
    if src.is_dir():
        yield from read_folder(src, intrinsics, depth_scale, every, max_frames, skipped)
    elif src.is_file() and src.suffix.lower() in RECORDING_SUFFIXES:
        for kept, frame in enumerate(read_recording(src, every), start=1):  # only kept frames are aligned, copied
            if max_frames is not None and kept > max_frames:
                raise _too_many(kept, every, max_frames)
            yield frame
            del frame  # held by the caller only
    else:
        raise ImportError_(f"{src} is neither a folder of RGB-D images nor a .bag/.db3 recording",
                           code="bad_source")


def read_frames(source: str | Path, intrinsics: Intrinsics | None = None, depth_scale: float = 0.001,
                every: int = 1, max_frames: int | None = MAX_FRAMES,
                skipped: list[dict] | None = None) -> list[RGBDFrame]:
    """The frames of ``source`` (folder or recording) to import, keeping one in ``every`` while reading
    (``iter_frames``); the frames left out are appended to ``skipped`` and counted in one warning line.
    At least ``MIN_FRAMES`` usable ones (``no_frames`` otherwise, with the counts)."""
    skipped = [] if skipped is None else skipped
    before = len(skipped)
    frames = list(iter_frames(source, intrinsics, depth_scale, every, max_frames, skipped))
    left_out = len(skipped) - before
    if left_out:
        log.warning("%d of %d frames skipped; %d usable", left_out, left_out + len(frames), len(frames))
    if len(frames) < MIN_FRAMES:
        raise ImportError_(f"a sequence needs at least {MIN_FRAMES} usable frames, found {len(frames)}"
                           + (f" ({left_out} skipped)" if left_out else ""), code="no_frames",
                           detail={"usable": len(frames), "skipped": left_out, "frames_skipped": skipped[before:][:20]})
    return frames

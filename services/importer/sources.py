"""Reading a fixed-camera sequence: a folder of color + depth images, or a RealSense recording.

A folder holds color and depth images paired by the last number in their names, in that number's
order (the turn order): ``rgb/align_test7.png`` with ``depth/align_test_depth7.png``, or ``color_0007.png``
with ``depth_0007.png`` side by side. Depth is 16-bit, aligned to color, in ``depth_scale`` units.
Intrinsics come from the caller (or ``intrinsics.json`` in the folder); a recording carries its own.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from PIL import Image

from common.messages import Intrinsics, RGBDFrame
from services.importer.errors import ImportError_

IMAGE_SUFFIXES = (".png", ".tif", ".tiff")
RECORDING_SUFFIXES = (".bag", ".db3")
_NUMBER = re.compile(r"(\d+)(?!.*\d)")


def parse_intrinsics(text: str, width: int = 0, height: int = 0) -> Intrinsics:
    """``fx,fy,cx,cy`` (pixels) or a JSON file with those keys (and optionally width/height)."""
    p = Path(text)
    try:
        if p.is_file():
            d = json.loads(p.read_text())
            vals = [float(d[k]) for k in ("fx", "fy", "cx", "cy")]
            width, height = int(d.get("width", width)), int(d.get("height", height))
        else:
            vals = [float(v) for v in text.split(",")]
    except (ValueError, KeyError, json.JSONDecodeError) as exc:
        raise ImportError_(f"cannot read intrinsics from {text!r}: {exc}", code="bad_intrinsics") from None
    if len(vals) != 4 or not all(np.isfinite(vals)) or vals[0] <= 0 or vals[1] <= 0:
        raise ImportError_("intrinsics must be four numbers fx,fy,cx,cy with fx, fy > 0", code="bad_intrinsics",
                           detail={"given": text})
    return Intrinsics(width=width, height=height, fx=vals[0], fy=vals[1], cx=vals[2], cy=vals[3])


def _numbered(files: list[Path]) -> dict[int, Path]:
    out: dict[int, Path] = {}
    for f in files:
        m = _NUMBER.search(f.stem)
        if m is not None:
            out.setdefault(int(m.group(1)), f)
    return out


def _images(folder: Path) -> list[Path]:
    return sorted(f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)


def pair_images(folder: Path) -> list[tuple[int, Path, Path]]:
    """(number, color, depth) for every numbered pair, in number order."""
    sub_color = next((folder / n for n in ("rgb", "color", "colour") if (folder / n).is_dir()), None)
    if sub_color is not None and (folder / "depth").is_dir():
        colors, depths = _numbered(_images(sub_color)), _numbered(_images(folder / "depth"))
    else:
        files = _images(folder)
        colors = _numbered([f for f in files if "depth" not in f.stem.lower()])
        depths = _numbered([f for f in files if "depth" in f.stem.lower()])
    common = sorted(set(colors) & set(depths))
    if not common:
        raise ImportError_(f"no numbered color/depth image pairs in {folder}", code="no_frames",
                           detail={"color": len(colors), "depth": len(depths),
                                   "layouts": ["rgb/NAME{N}.png + depth/NAME{N}.png",
                                               "color_{N}.png + depth_{N}.png in one folder"]})
    lonely = sorted(set(colors) ^ set(depths))
    if lonely:
        raise ImportError_("some images have no partner (color without depth or the reverse)",
                           code="unpaired_frames", detail={"numbers": lonely[:20]})
    return [(n, colors[n], depths[n]) for n in common]


def read_folder(folder: Path, intrinsics: Intrinsics | None, depth_scale: float) -> Iterator[RGBDFrame]:
    """Frames of an image folder, in turn order; the base pose is left as identity (set later)."""
    if intrinsics is None and (folder / "intrinsics.json").is_file():
        intrinsics = parse_intrinsics(str(folder / "intrinsics.json"))
    if intrinsics is None:
        raise ImportError_("a folder of images needs the color camera's intrinsics (--intrinsics fx,fy,cx,cy "
                           "or intrinsics.json in the folder)", code="bad_intrinsics")
    if not (depth_scale > 0 and np.isfinite(depth_scale)):
        raise ImportError_("depth_scale must be positive", code="bad_value", detail={"depth_scale": depth_scale})
    for n, cpath, dpath in pair_images(folder):
        try:
            color = np.asarray(Image.open(cpath).convert("RGB"), dtype=np.uint8)
            depth_img = Image.open(dpath)
            depth = np.asarray(depth_img)
        except OSError as exc:
            raise ImportError_(f"cannot read image pair {n}: {exc}", code="bad_image") from None
        if depth.ndim != 2 or depth.dtype.kind not in "ui":
            raise ImportError_(f"depth image {dpath.name} is not single-channel 16-bit", code="bad_image",
                               detail={"shape": list(depth.shape), "dtype": str(depth.dtype)})
        if depth.shape != color.shape[:2]:
            raise ImportError_(f"pair {n}: depth {depth.shape} and color {color.shape[:2]} differ (not aligned)",
                               code="bad_image")
        h, w = depth.shape
        K = Intrinsics(width=w, height=h, fx=intrinsics.fx, fy=intrinsics.fy, cx=intrinsics.cx, cy=intrinsics.cy)
        yield RGBDFrame(color=color, depth=depth.astype(np.uint16), depth_scale=float(depth_scale), intrinsics=K,
                        T_base_camera=np.eye(4), seq=n,
                        meta={"source_color": cpath.name, "source_depth": dpath.name})


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

"""Reading a folder of colour + depth PNG frames: the pairing rule, the intrinsics, one pair as a frame.

One home for what both the ``png_folder`` camera and ``objscan import`` read. A folder holds colour and
depth images paired by the last number in their names, in that number's order (the capture order):
``rgb/align_test7.png`` with ``depth/align_test_depth7.png``, or ``color_0007.png`` with
``depth_0007.png`` side by side. Depth is 16-bit, aligned to colour, in ``depth_scale`` units.
Intrinsics are ``fx,fy,cx,cy`` or a JSON file (``intrinsics.json`` in the folder by default).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
from PIL import Image

from common.messages import Intrinsics, RGBDFrame
from services.camera.errors import CameraError

IMAGE_SUFFIXES = (".png", ".tif", ".tiff")
INTRINSICS_FILE = "intrinsics.json"
_NUMBER = re.compile(r"(\d+)(?!.*\d)")


class FrameFolderError(CameraError):
    """The folder cannot be read as RGB-D frames; ``code`` says why: ``bad_intrinsics``, ``no_frames``,
    ``unpaired_frames``, ``bad_image``."""

    code = "bad_frame_folder"


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
        raise FrameFolderError(f"cannot read intrinsics from {text!r}: {exc}", code="bad_intrinsics") from None
    if len(vals) != 4 or not all(np.isfinite(vals)) or vals[0] <= 0 or vals[1] <= 0:
        raise FrameFolderError("intrinsics must be four numbers fx,fy,cx,cy with fx, fy > 0", code="bad_intrinsics",
                               detail={"given": text})
    return Intrinsics(width=width, height=height, fx=vals[0], fy=vals[1], cx=vals[2], cy=vals[3])


def folder_intrinsics(folder: Path, given: Intrinsics | None) -> Intrinsics:
    """``given``, else the folder's ``intrinsics.json``; ``bad_intrinsics`` when neither exists."""
    if given is None and (folder / INTRINSICS_FILE).is_file():
        given = parse_intrinsics(str(folder / INTRINSICS_FILE))
    if given is None:
        raise FrameFolderError("a folder of images needs the colour camera's intrinsics (fx,fy,cx,cy, "
                               f"or {INTRINSICS_FILE} in the folder)", code="bad_intrinsics",
                               detail={"folder": str(folder)})
    return given


def _numbered(files: list[Path]) -> dict[int, Path]:
    out: dict[int, Path] = {}
    for f in files:
        m = _NUMBER.search(f.stem)
        if m is not None:
            out.setdefault(int(m.group(1)), f)
    return out


def _images(folder: Path) -> list[Path]:
    return sorted(f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)


def match_images(folder: Path) -> tuple[list[tuple[int, Path, Path]], list[tuple[int, str]]]:
    """(number, color, depth) for every numbered pair, in number order, and the numbers of the images with no
    partner (``(n, "color" | "depth")``: the one that is there). ``no_frames`` when nothing pairs."""
    if not folder.is_dir():
        raise FrameFolderError(f"{folder} is not a folder", code="no_frames", detail={"folder": str(folder)})
    sub_color = next((folder / n for n in ("rgb", "color", "colour") if (folder / n).is_dir()), None)
    if sub_color is not None and (folder / "depth").is_dir():
        colors, depths = _numbered(_images(sub_color)), _numbered(_images(folder / "depth"))
    else:
        files = _images(folder)
        colors = _numbered([f for f in files if "depth" not in f.stem.lower()])
        depths = _numbered([f for f in files if "depth" in f.stem.lower()])
    common = sorted(set(colors) & set(depths))
    if not common:
        raise FrameFolderError(f"no numbered color/depth image pairs in {folder}", code="no_frames",
                               detail={"color": len(colors), "depth": len(depths),
                                       "layouts": ["rgb/NAME{N}.png + depth/NAME{N}.png",
                                                   "color_{N}.png + depth_{N}.png in one folder"]})
    lonely = [(n, "color" if n in colors else "depth") for n in sorted(set(colors) ^ set(depths))]
    return [(n, colors[n], depths[n]) for n in common], lonely


def pair_images(folder: Path) -> list[tuple[int, Path, Path]]:
    """(number, color, depth) for every numbered pair, in number order; ``unpaired_frames`` when an image has
    no partner (a camera replaying the folder must not drop frames silently)."""
    pairs, lonely = match_images(folder)
    if lonely:
        raise FrameFolderError("some images have no partner (color without depth or the reverse)",
                               code="unpaired_frames", detail={"numbers": [n for n, _ in lonely][:20]})
    return pairs


def read_pair(n: int, cpath: Path, dpath: Path, intrinsics: Intrinsics, depth_scale: float) -> RGBDFrame:
    """Pair ``n`` as an aligned frame (``seq`` = n, identity pose: the folder knows no pose)."""
    try:
        color = np.asarray(Image.open(cpath).convert("RGB"), dtype=np.uint8)
        depth = np.asarray(Image.open(dpath))
    except OSError as exc:
        raise FrameFolderError(f"cannot read image pair {n}: {exc}", code="bad_image") from None
    if depth.ndim != 2 or depth.dtype.kind not in "ui":
        raise FrameFolderError(f"depth image {dpath.name} is not single-channel 16-bit", code="bad_image",
                               detail={"shape": list(depth.shape), "dtype": str(depth.dtype)})
    if depth.shape != color.shape[:2]:
        raise FrameFolderError(f"pair {n}: depth {depth.shape} and color {color.shape[:2]} differ (not aligned)",
                               code="bad_image")
    h, w = depth.shape
    K = Intrinsics(width=w, height=h, fx=intrinsics.fx, fy=intrinsics.fy, cx=intrinsics.cx, cy=intrinsics.cy)
    return RGBDFrame(color=color, depth=depth.astype(np.uint16), depth_scale=float(depth_scale), intrinsics=K,
                     T_base_camera=np.eye(4), seq=n, meta={"source_color": cpath.name, "source_depth": dpath.name})

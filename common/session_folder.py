"""The session folder: how captured scans live on disk.

Layout (documented in docs/session-folder.md)::

    SESSION/session.json                       object, profile, seed, views [{index, commanded_turn_deg}]
    SESSION/view_KK/scan_J/color.png           8-bit RGB
    SESSION/view_KK/scan_J/depth.png           16-bit depth, metres = value * depth_scale
    SESSION/view_KK/scan_J/meta.json           intrinsics, depth_scale, T_base_camera (+ ground truth in sim)
    SESSION/model.ply, SESSION/report.json     the result: the model and the run's figures (``MODEL_FILE``,
                                               ``REPORT_FILE``), written by whoever registers the views

The orchestrator writes it as it captures, the camera's replay backend and ``objscan reconstruct`` read
it. Every file is written atomically (``common.atomic``: unique temporary name, fsync, rename, folder
fsync), so a crash never leaves a half-written scan
that a reader would take for a real one. Keys a reader does not know are ignored.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from common.atomic import atomic_write_bytes
from common.errors import ObjscanError
from common.messages import Intrinsics, RGBDFrame

SESSION_FILE = "session.json"
MODEL_FILE = "model.ply"
"""The registered model (binary PLY, colors and normals) a finished run leaves in its folder."""
REPORT_FILE = "report.json"
"""The run's figures and decisions, beside the model (docs/session-folder.md)."""
__all__ = ["atomic_write_bytes", "atomic_write_json"]  # re-exported: the one atomic writer is common.atomic


class SessionFolderError(ObjscanError):
    """A session folder is missing, incomplete or corrupt."""

    code = "bad_session"


def new_folder_refusal(path: Path, allowed: frozenset[str] = frozenset()) -> str | None:
    """Why ``path`` cannot receive a new session, or None when it can: it must be absent or an empty folder
    (names in ``allowed`` aside). Every writer of a new session (a scan, an import) asks this before it
    writes anything, so a session never merges into a folder it did not create."""
    path = Path(path)
    if not path.exists():
        return None
    if not path.is_dir():
        return "is not a folder"
    if any(p.name not in allowed for p in path.iterdir()):
        return "is not an empty folder"
    return None


def view_dir(session: Path, view: int) -> Path:
    return Path(session) / f"view_{view:02d}"


def scan_dir(session: Path, view: int, scan: int) -> Path:
    return view_dir(session, view) / f"scan_{scan}"


def atomic_write_json(path: Path, obj: Any) -> None:
    atomic_write_bytes(path, json.dumps(obj, indent=2, default=json_default).encode())


def json_default(o: Any) -> Any:
    """``json.dumps(default=...)`` for numpy arrays and scalars and paths (shared by every JSON writer)."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _png_bytes(image: Image.Image) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


def write_scan(session: Path, view: int, scan: int, frame: RGBDFrame, extra: dict[str, Any] | None = None) -> Path:
    """Persist one capture; meta.json is written last so its presence marks a complete scan."""
    d = scan_dir(session, view, scan)
    atomic_write_bytes(d / "color.png", _png_bytes(Image.fromarray(np.ascontiguousarray(frame.color), "RGB")))
    depth = np.ascontiguousarray(frame.depth.astype("<u2"))
    atomic_write_bytes(d / "depth.png", _png_bytes(Image.fromarray(depth)))
    meta: dict[str, Any] = {
        "intrinsics": frame.intrinsics.as_dict(),
        "depth_scale": frame.depth_scale,
        "T_base_camera": frame.T_base_camera,
        "stamp": frame.stamp,
        "seq": frame.seq,
    }
    if frame.T_base_camera_true is not None:
        meta["ground_truth"] = {"T_base_camera": frame.T_base_camera_true}
    for key, value in (frame.meta or {}).items():
        meta.setdefault(key, value)
    if extra:
        meta.update(extra)
    atomic_write_json(d / "meta.json", meta)
    return d


def scan_complete(session: Path, view: int, scan: int) -> bool:
    return (scan_dir(session, view, scan) / "meta.json").is_file()


def read_scan(session: Path, view: int, scan: int) -> RGBDFrame:
    """Load one scan back into an ``RGBDFrame`` (ground truth included when the sim recorded it)."""
    d = scan_dir(session, view, scan)
    return read_scan_dir(d)


def read_scan_dir(d: Path) -> RGBDFrame:
    d = Path(d)
    try:
        meta = json.loads((d / "meta.json").read_text())
        color = np.asarray(Image.open(d / "color.png").convert("RGB"), dtype=np.uint8)
        depth_img = Image.open(d / "depth.png")
        depth = np.asarray(depth_img).astype(np.uint16)
    except FileNotFoundError as exc:
        raise SessionFolderError(f"scan folder {d} is incomplete: {exc.filename} missing") from None
    except (OSError, ValueError, json.JSONDecodeError) as exc:
        raise SessionFolderError(f"scan folder {d} is corrupt: {exc}") from None
    try:
        intr = Intrinsics.from_dict(meta["intrinsics"])
        T = np.asarray(meta["T_base_camera"], dtype=np.float64).reshape(4, 4)
        depth_scale = float(meta["depth_scale"])
    except (KeyError, TypeError, ValueError) as exc:
        raise SessionFolderError(f"{d / 'meta.json'} lacks a valid {exc}") from None
    gt = meta.get("ground_truth", {}).get("T_base_camera")
    known = {"intrinsics", "depth_scale", "T_base_camera", "stamp", "seq", "ground_truth"}
    return RGBDFrame(
        color=color, depth=depth, depth_scale=depth_scale, intrinsics=intr, T_base_camera=T,
        stamp=float(meta.get("stamp", 0.0)), seq=int(meta.get("seq", 0)),
        T_base_camera_true=None if gt is None else np.asarray(gt, dtype=np.float64).reshape(4, 4),
        meta={k: v for k, v in meta.items() if k not in known},
    )


@dataclass
class SessionInfo:
    """What session.json says: the views and their commanded turns, plus free-form metadata."""

    path: Path
    views: list[dict[str, Any]]
    data: dict[str, Any]

    def commanded_turn_deg(self, view: int) -> float:
        """Cumulative commanded turn of the object at ``view`` relative to view 0, in degrees."""
        for v in self.views:
            if int(v["index"]) == view:
                return float(v.get("commanded_turn_deg", 0.0))
        raise SessionFolderError(f"view {view} is not listed in {self.path / SESSION_FILE}")

    def scans(self, view: int) -> list[int]:
        """Indices of the complete scans of ``view`` found on disk, sorted."""
        vd = view_dir(self.path, view)
        out = []
        for d in sorted(vd.glob("scan_*")) if vd.is_dir() else []:
            suffix = d.name.removeprefix("scan_")
            if suffix.isdigit() and (d / "meta.json").is_file():
                out.append(int(suffix))
        return sorted(out)


def read_session(session: Path) -> SessionInfo:
    """Read session.json; when absent, infer the views from the folders (turns unknown, taken as 0)."""
    session = Path(session)
    if not session.is_dir():
        raise SessionFolderError(f"session folder {session} does not exist")
    path = session / SESSION_FILE
    if path.is_file():
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise SessionFolderError(f"{path} is not valid JSON: {exc}") from None
        views = data.get("views", [])
    else:
        data = {}
        views = [{"index": int(d.name[5:]), "commanded_turn_deg": 0.0}
                 for d in sorted(session.glob("view_*")) if d.name[5:].isdigit()]
    if not views:
        raise SessionFolderError(f"{session} lists no views")
    return SessionInfo(path=session, views=sorted(views, key=lambda v: int(v["index"])), data=data)


def write_session(session: Path, data: dict[str, Any]) -> None:
    """Write session.json atomically; ``data['views']`` lists {index, commanded_turn_deg, ...}."""
    atomic_write_json(Path(session) / SESSION_FILE, data)

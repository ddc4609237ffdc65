"""``objscan import`` within bounds: it writes only a new session folder, and it streams its frames.

- ``--out`` must be absent or empty, like a new scan's: a finished session given as ``--out`` used to get
  some of its views and its ``session.json`` replaced while its journal, model and recording stayed.
- ``--every`` is applied while reading: a folder decodes only the pairs it keeps, a recording reads past
  the others without aligning or copying them; it used to load every frame, then keep one in N. Checked
  on what is decoded and held (weak references to every frame made), not on the process's memory.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import weakref
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from common.messages import Intrinsics, RGBDFrame
from services.camera.png_folder import frames as png_frames
from services.importer import sources
from services.importer.errors import ImportError_, OutNotEmpty
from services.importer.session import import_sequence
from services.importer.sources import iter_frames, parse_intrinsics, read_frames

REPO = Path(__file__).resolve().parents[2]


def _image_folder(folder: Path, n: int, size: tuple[int, int] = (6, 8)) -> Path:
    """``n`` numbered color/depth pairs, each colour image tagged with its number (red channel)."""
    folder.mkdir(parents=True, exist_ok=True)
    h, w = size
    for k in range(n):
        Image.fromarray(np.full((h, w, 3), k % 256, np.uint8)).save(folder / f"color_{k}.png")
        Image.fromarray(np.full((h, w), 500, np.uint16)).save(folder / f"depth_{k}.png")
    (folder / "intrinsics.json").write_text(json.dumps({"fx": 5.0, "fy": 5.0, "cx": w / 2, "cy": h / 2}))
    return folder


class _Alive:
    """Weak references to every frame a reader made: how many were decoded, and the most alive at once."""

    def __init__(self) -> None:
        self.refs: list[weakref.ref] = []
        self.peak = 0

    def made(self, frame: RGBDFrame) -> RGBDFrame:
        self.refs.append(weakref.ref(frame))
        self.peak = max(self.peak, self.alive())
        return frame

    def alive(self) -> int:
        return sum(r() is not None for r in self.refs)


def _snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _import_cli(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "services.cli.main", "import", *args], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=180)


def test_import_into_a_non_empty_folder_is_refused_with_nothing_written(tmp_path):
    """A finished session as ``--out``: refused with ``out_not_empty`` before a frame is read, every file as it
    was; an absent or empty ``--out`` goes on to the import itself (here: a wall, no table)."""
    src = _image_folder(tmp_path / "src", 4, size=(60, 80))
    session = tmp_path / "finished"
    (session / "view_00" / "scan_0").mkdir(parents=True)
    (session / "session.json").write_text(json.dumps({"object": "milk", "views": [{"index": 0}]}))
    (session / "journal.json").write_text(json.dumps({"status": "done"}))
    (session / "view_00" / "scan_0" / "meta.json").write_text("{}")
    (session / "model.ply").write_bytes(b"ply\n")
    before = _snapshot(session)
    out = _import_cli(str(src), "--out", str(session), "--intrinsics", "50,50,40,30")
    assert out.returncode != 0
    assert "out_not_empty" in out.stdout + out.stderr, out.stdout[-2000:] + out.stderr[-2000:]
    assert _snapshot(session) == before  # nothing written, nothing replaced
    assert sorted(p.name for p in session.iterdir()) == ["journal.json", "model.ply", "session.json", "view_00"]

    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    with pytest.raises(OutNotEmpty) as exc:
        import_sequence(src, a_file, parse_intrinsics("50,50,40,30"))
    assert exc.value.code == "out_not_empty" and a_file.read_text() == "keep me"

    empty = tmp_path / "empty"
    empty.mkdir()
    for target in (empty, tmp_path / "absent"):  # accepted: the import fails later, on the frames themselves
        with pytest.raises(ImportError_) as exc:
            import_sequence(src, target, parse_intrinsics("50,50,40,30"))
        assert exc.value.code == "no_table", exc.value


def test_every_is_applied_while_reading_an_image_folder(tmp_path, monkeypatch):
    """300 pairs, ``every=25``: 12 decoded, never more than those 12 alive (was: 300 decoded and held)."""
    folder = _image_folder(tmp_path / "long", 300)
    alive = _Alive()
    read_pair = png_frames.read_pair
    monkeypatch.setattr(png_frames, "read_pair", lambda *a, **k: alive.made(read_pair(*a, **k)))
    frames = read_frames(folder, every=25)
    assert len(alive.refs) == 12  # only the kept pairs were decoded
    assert alive.peak <= 12
    assert [int(f.color[0, 0, 0]) for f in frames] == [k % 256 for k in range(0, 300, 25)]  # the right ones, in order


@pytest.mark.timeout(180)
def test_every_is_applied_while_reading_a_recording(tmp_path, monkeypatch):
    """A 12-frame ``.db3`` (librealsense's own recorder) read with ``every=4``: only frames 0, 4, 8 are captured
    (aligned and copied), the others are read past, and no frame is held beyond those kept (was: all 12
    captured and held, then one in 4 kept)."""
    pytest.importorskip("pyrealsense2")
    from bench.software_d435 import record_db3
    from services.camera.realsense.camera import RealSenseCamera
    from tests.camera.test_realsense_playback import SPEC, _frames

    base = _frames()
    pairs = []
    for k in range(12):
        depth, color = base[k % len(base)]
        color = color.copy()
        color[:8, :8] = k  # the frame's number, in the corner
        pairs.append((depth, color))
    path = record_db3(tmp_path / "long.db3", pairs, SPEC)
    alive = _Alive()
    capture = RealSenseCamera.capture
    monkeypatch.setattr(RealSenseCamera, "capture", lambda self, *a: alive.made(capture(self, *a)))
    frames = list(iter_frames(path, every=4))
    assert [int(f.color[2, 2, 0]) for f in frames] == [0, 4, 8] and [f.seq for f in frames] == [0, 4, 8]
    assert len(alive.refs) == 3  # only the kept frames were aligned and copied
    assert alive.peak <= 3


def test_a_sequence_beyond_max_frames_is_refused_before_decoding(tmp_path, monkeypatch):
    folder = _image_folder(tmp_path / "long", 40)
    calls = []
    monkeypatch.setattr(png_frames, "read_pair", lambda *a, **k: calls.append(a))
    with pytest.raises(ImportError_) as exc:
        read_frames(folder, parse_intrinsics("5,5,4,3"), every=2, max_frames=10)
    assert exc.value.code == "too_many_frames"
    assert exc.value.detail["frames"] == 40 and exc.value.detail["every_needed"] == 4
    assert not calls  # refused from the file names alone
    assert len(read_frames(folder, every=4, max_frames=10)) == 10  # the suggested --every fits


def test_too_many_frames_from_a_recording_stops_reading(tmp_path, monkeypatch):
    """A long recording past ``max_frames``: reading stops at the first frame too many, not at its end."""
    path = tmp_path / "long.bag"
    path.write_bytes(b"")
    intr = Intrinsics(fx=5.0, fy=5.0, cx=4.0, cy=3.0, width=8, height=6)
    captured = []

    def recording(p: Path, every: int):
        for k in range(0, 10_000, every):  # what the reader captures: one frame in ``every``
            captured.append(k)
            yield RGBDFrame(color=np.zeros((6, 8, 3), np.uint8), depth=np.zeros((6, 8), np.uint16),
                            depth_scale=0.001, intrinsics=intr, T_base_camera=np.eye(4), seq=k)

    monkeypatch.setattr(sources, "read_recording", recording)
    with pytest.raises(ImportError_) as exc:
        read_frames(path, every=3, max_frames=20)
    assert exc.value.code == "too_many_frames"
    assert len(captured) == 21  # stopped at the 21st kept frame, not at the end of the recording

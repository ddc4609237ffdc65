"""Imperfect folders: frames without a partner, unreadable or empty images, depth of another size are skipped
with a one-line warning each and a count; only a folder with too few usable frames is refused."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from PIL import Image

from services.importer.errors import ImportError_
from services.importer.sources import read_frames


def _pair(folder, n: int, *, color: bool = True, depth: bool = True, depth_shape=(4, 6)) -> None:
    if color:
        Image.fromarray(np.full((4, 6, 3), n, np.uint8)).save(folder / f"color_{n}.png")
    if depth:
        Image.fromarray(np.full(depth_shape, 500, np.uint16)).save(folder / f"depth_{n}.png")


def _folder(tmp_path):
    (tmp_path / "intrinsics.json").write_text(json.dumps({"fx": 5.0, "fy": 5.0, "cx": 3.0, "cy": 2.0}))
    for n in (1, 2, 5, 7):
        _pair(tmp_path, n)
    _pair(tmp_path, 3, depth=False)  # colour without depth
    for n in (8, 9):
        _pair(tmp_path, n, color=False)  # depth without colour (a depth stream recorded longer)
    _pair(tmp_path, 4, depth_shape=(8, 12))  # depth of another size: not aligned to the colour
    _pair(tmp_path, 6, depth=False)
    (tmp_path / "depth_6.png").write_bytes(b"not a png")  # unreadable
    return tmp_path


def test_a_folder_with_unpaired_frames_imports_the_paired_ones(tmp_path, caplog):
    folder = _folder(tmp_path)
    skipped: list[dict] = []
    with caplog.at_level(logging.WARNING, logger="objscan.import"):
        frames = read_frames(folder, skipped=skipped)
    assert [f.seq for f in frames] == [1, 2, 5, 7]  # the usable pairs, in order
    assert [int(f.color[0, 0, 0]) for f in frames] == [1, 2, 5, 7]
    by_frame = {s["frame"]: s["code"] for s in skipped}
    assert by_frame == {3: "unpaired_frames", 8: "unpaired_frames", 9: "unpaired_frames", 4: "bad_image",
                        6: "bad_image"}
    lines = [r.getMessage() for r in caplog.records if r.name == "objscan.import"]
    assert len(lines) == len(skipped) + 1  # one line per skipped frame, and the count
    assert all("\n" not in line for line in lines)
    assert "5 of 9 frames skipped" in lines[-1]


def test_every_applies_to_the_paired_frames_of_an_imperfect_folder(tmp_path):
    """Pairing needs no decoding, so ``every`` counts the pairs and an unpaired image never shifts it."""
    folder = _folder(tmp_path)
    for name in ("color_4.png", "depth_4.png", "color_6.png", "depth_6.png"):
        (folder / name).unlink()
    for n in (10, 11):
        _pair(folder, n)
    frames = read_frames(folder, every=2, skipped=[])
    assert [f.seq for f in frames] == [1, 5, 10]  # pairs 1 2 5 7 10 11: one in two


def test_a_folder_with_too_few_usable_frames_is_refused_with_the_count(tmp_path):
    (tmp_path / "intrinsics.json").write_text(json.dumps({"fx": 5.0, "fy": 5.0, "cx": 3.0, "cy": 2.0}))
    _pair(tmp_path, 1)
    _pair(tmp_path, 2)
    for n in (3, 4, 5):
        _pair(tmp_path, n, color=False)
    with pytest.raises(ImportError_) as exc:
        read_frames(tmp_path)
    assert exc.value.code == "no_frames"
    assert exc.value.detail["usable"] == 2 and exc.value.detail["skipped"] == 3


def test_the_png_folder_camera_still_refuses_unpaired_frames(tmp_path):
    """A camera replaying a folder must not silently drop frames: only the import is lenient."""
    from services.camera.png_folder.frames import FrameFolderError, pair_images

    _pair(tmp_path, 1)
    _pair(tmp_path, 2, color=False)
    with pytest.raises(FrameFolderError) as exc:
        pair_images(tmp_path)
    assert exc.value.code == "unpaired_frames"

"""A model library never deletes what it did not create.

Why: ``ModelLibrary(path)`` on any folder created ``entries/``, ``.staging/``, ``.trash/`` there and its
tidy-up removed whatever it found in them, so the orchestrator's ``run`` parameter ``library`` let a network
request delete folders.
"""

from __future__ import annotations

import sqlite3

import pytest

from services.library.errors import LibraryError
from services.library.store import ENTRIES, MARKER, STAGING, TRASH, ModelLibrary
from tests.library.helpers import FAST_DESCRIPTORS, box_surface


def _plant(root):
    """Someone's folder that happens to have the library's sub-folder names."""
    files = {root / ENTRIES / "thesis" / "chapter1.tex": b"precious", root / STAGING / "draft.txt": b"draft",
             root / TRASH / "old" / "keep.me": b"keep", root / "notes.txt": b"notes"}
    for path, data in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return files


def test_a_foreign_folder_is_refused_and_untouched(tmp_path):
    files = _plant(tmp_path / "home")
    before = sorted(p.relative_to(tmp_path) for p in (tmp_path / "home").rglob("*"))
    with pytest.raises(LibraryError) as err:
        ModelLibrary(tmp_path / "home", descriptor_config=FAST_DESCRIPTORS)
    assert err.value.code == "not_a_library"
    assert sorted(p.relative_to(tmp_path) for p in (tmp_path / "home").rglob("*")) == before
    assert all(p.read_bytes() == data for p, data in files.items())


def test_foreign_items_inside_a_library_are_left_alone(tmp_path):
    root = tmp_path / "lib"
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    entry = lib.add(box_surface(seed=1), {"object_name": "box"})
    assert (root / MARKER).is_file()
    (root / ENTRIES / "README").write_text("mine")
    (root / ENTRIES / "photos").mkdir()
    (root / STAGING / "x.123").mkdir()  # not a name an add makes
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert sorted(lib.last_reconcile.foreign) == sorted([f"{ENTRIES}/README", f"{ENTRIES}/photos",
                                                         f"{STAGING}/x.123"])
    assert (root / ENTRIES / "README").read_text() == "mine" and (root / ENTRIES / "photos").is_dir()
    assert (root / STAGING / "x.123").is_dir()
    assert [e.id for e in lib.list()] == [entry]


def test_an_empty_or_absent_folder_becomes_a_library_and_an_older_library_still_opens(tmp_path):
    (tmp_path / "empty").mkdir()
    ModelLibrary(tmp_path / "empty", descriptor_config=FAST_DESCRIPTORS)
    assert (tmp_path / "empty" / MARKER).is_file()
    old = tmp_path / "old"
    lib = ModelLibrary(old, descriptor_config=FAST_DESCRIPTORS)
    (old / MARKER).unlink()  # a library from before the marker: index.sqlite with our schema
    assert sqlite3.connect(old / "index.sqlite").execute("PRAGMA user_version").fetchone()[0] == 1
    del lib
    ModelLibrary(old, descriptor_config=FAST_DESCRIPTORS)
    assert (old / MARKER).is_file()

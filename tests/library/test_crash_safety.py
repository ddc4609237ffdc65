"""The library survives a crash at any point of an add or a delete: no orphan folder, no half entry.

Two ways to crash at each stage (``ADD_STAGES`` / ``DELETE_STAGES``): an exception raised there (the add
or delete must roll back or finish on the spot), and a real ``SIGKILL`` of a subprocess stopped there (the
next open must reconcile by the rule in services/library/store.py: before the rename nothing happened,
after it the entry is indexed).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from services.library import ModelLibrary, ModelMetadata
from services.library.store import ADD_STAGES, DELETE_STAGES, ENTRIES, METADATA_FILE, MODEL_FILE, STAGING, TRASH
from tests.library.helpers import FAST_DESCRIPTORS, CrashingLibrary, box_surface, crash_child

COMMITTED_ADD = {"renamed", "row_inserted", "committed"}  # the rename into entries/ is the commit point


class Crash(Exception):
    pass


def _raise_at(stage: str):
    def hook(s: str) -> None:
        if s == stage:
            raise Crash(stage)
    return hook


def assert_consistent(lib: ModelLibrary) -> None:
    """Every row has its complete folder, every folder has its row, and nothing is in flight."""
    rows = {e.id for e in lib.list()}
    folders = {p.name for p in (lib.root / ENTRIES).iterdir()}
    assert rows == folders
    for entry_id in rows:
        assert (lib.root / ENTRIES / entry_id / MODEL_FILE).is_file()
        assert json.loads((lib.root / ENTRIES / entry_id / METADATA_FILE).read_text())["id"] == entry_id
    assert not any((lib.root / STAGING).iterdir()) and not any((lib.root / TRASH).iterdir())


@pytest.mark.parametrize("stage", ADD_STAGES)
def test_exception_during_add_leaves_nothing(tmp_path, stage):
    root = tmp_path / "lib"
    ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS).add(box_surface(seed=1), {"object_name": "before"})
    lib = CrashingLibrary(root, _raise_at(stage), descriptor_config=FAST_DESCRIPTORS)
    with pytest.raises(Crash):
        lib.add(box_surface(), {"object_name": "crashed"})
    assert [e.metadata.object_name for e in lib.list()] == ["before"]
    assert_consistent(lib)
    again = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert not again.last_reconcile.changed()  # the rollback already left it clean
    again.add(box_surface(), {"object_name": "after"})
    assert sorted(e.metadata.object_name for e in again.list()) == ["after", "before"]


@pytest.mark.parametrize("stage", DELETE_STAGES)
def test_exception_during_delete_finishes_the_delete(tmp_path, stage):
    root = tmp_path / "lib"
    base = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    keep = base.add(box_surface(seed=1), {"object_name": "keep"})
    gone = base.add(box_surface(seed=2), {"object_name": "gone"})
    lib = CrashingLibrary(root, _raise_at(stage), descriptor_config=FAST_DESCRIPTORS)
    with pytest.raises(Crash):
        lib.delete(gone)
    assert [e.id for e in lib.list()] == [keep]
    assert_consistent(lib)


@pytest.fixture(scope="module")
def forkserver():
    """Children forked from a server that has imported the library once (a fresh interpreter per kill
    would pay the Open3D/scikit-learn import each time; a plain fork of the test process risks Open3D's
    OpenMP state, see ecosystem-notes: use spawn or forkserver)."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["services.library", "tests.library.helpers"])
    return ctx


def _run_child(ctx, root: Path, op: str, stage: str, target: str | None = None) -> int:
    proc = ctx.Process(target=crash_child, args=(str(root), op, stage, target))
    proc.start()
    proc.join(timeout=120)
    assert not proc.is_alive(), "child did not finish"
    return proc.exitcode


@pytest.mark.parametrize("stage", ADD_STAGES)
def test_process_killed_during_add_is_reconciled_on_open(tmp_path, forkserver, stage):
    root = tmp_path / "lib"
    before = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS).add(box_surface(seed=1), {"object_name": "before"})
    assert _run_child(forkserver, root, "add", stage) == -signal.SIGKILL
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert_consistent(lib)
    names = sorted(e.metadata.object_name for e in lib.list())
    if stage in COMMITTED_ADD:
        assert names == ["before", "killed"]
        killed = lib.list("killed")[0]
        assert killed.metadata.quality == {"chamfer_mm": 2.5} and killed.points == 3000
        assert lib.descriptors(killed.id)["views"].shape[0] >= 1
        expect_indexed = [] if stage == "committed" else [killed.id]
        assert lib.last_reconcile.indexed == expect_indexed
    else:
        assert names == ["before"]
        assert len(lib.last_reconcile.removed_staging) == 1  # the dead add's staging folder
    assert lib.get(before).metadata.object_name == "before"


@pytest.mark.parametrize("stage", DELETE_STAGES)
def test_process_killed_during_delete_is_reconciled_on_open(tmp_path, forkserver, stage):
    root = tmp_path / "lib"
    base = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    keep = base.add(box_surface(seed=1), {"object_name": "keep"})
    gone = base.add(box_surface(seed=2), {"object_name": "gone"})
    assert _run_child(forkserver, root, "delete", stage, gone) == -signal.SIGKILL
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert_consistent(lib)
    assert [e.id for e in lib.list()] == [keep]


def test_complete_unindexed_entry_is_indexed_but_a_corrupt_one_is_removed(tmp_path):
    root = tmp_path / "lib"
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    good = lib.add(box_surface(seed=1), ModelMetadata(object_name="good"))
    bad = lib.add(box_surface(seed=2), ModelMetadata(object_name="bad"))
    import sqlite3

    db = sqlite3.connect(root / "index.sqlite")
    db.execute("DELETE FROM models")  # as if both adds died between the rename and the row
    db.commit()
    db.close()
    with open(root / ENTRIES / bad / MODEL_FILE, "r+b") as fh:  # and one file got damaged
        fh.seek(-10, os.SEEK_END)
        fh.write(b"\0" * 10)
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert lib.last_reconcile.indexed == [good]
    assert lib.last_reconcile.removed_incomplete == [bad]
    assert [e.id for e in lib.list()] == [good]
    assert_consistent(lib)


def test_row_whose_files_vanished_is_dropped(tmp_path):
    import shutil

    root = tmp_path / "lib"
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    a = lib.add(box_surface(seed=1), {"object_name": "a"})
    b = lib.add(box_surface(seed=2), {"object_name": "b"})
    shutil.rmtree(root / ENTRIES / a)
    (root / ENTRIES / b / MODEL_FILE).unlink()
    lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    assert sorted(lib.last_reconcile.dropped_rows) == sorted([a, b])
    assert lib.list() == [] and not any((root / ENTRIES).iterdir())


def test_stray_staging_and_trash_folders_are_cleared(tmp_path):
    root = tmp_path / "lib"
    ModelLibrary(root)
    x, y = "x-20261124-101010-abcdef.123", "y-20261124-101011-012345.456"  # names an add/delete makes
    (root / STAGING / x).mkdir()
    (root / STAGING / x / MODEL_FILE).write_bytes(np.zeros(10).tobytes())
    (root / TRASH / y).mkdir()
    lib = ModelLibrary(root)
    assert lib.last_reconcile.removed_staging == [x] and lib.last_reconcile.removed_trash == [y]
    assert_consistent(lib)

"""The model library stores the export (the closed mesh and the asset folder) with the entry, whichever came
first: a session exported and then added (``objscan library add``), or added by the acquisition and exported
afterwards (``objscan scan --export``, ``objscan export``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from services.export import export_session
from services.library import ModelLibrary, add_session_model, attach_session_export
from services.library.store import ASSET_DIR, _complete_record
from tests.export.synthetic_session import make_box_session

QUICK = {"formats": ("stl", "mjcf"), "texture": False, "evaluate": False, "tolerance_m": 1.0}


@pytest.fixture
def session(tmp_path):
    return make_box_session(tmp_path / "session", cameras=6, width=120, height=90)[0]


def assert_entry_holds_the_export(lib: ModelLibrary, entry_id: str, out) -> None:  # noqa: ANN001
    entry = lib.get(entry_id)
    assert entry.mesh_path is not None and entry.asset_path is not None
    assert (entry.asset_path / "synthetic_box.xml").read_bytes() == (out / "synthetic_box.xml").read_bytes()
    assert json.loads((entry.asset_path / "export.json").read_text())["watertight"] is True
    assert entry.summary()["mesh"] and entry.summary()["asset"]
    # the entry's record lists the new files with their digests: a reconciling library keeps it whole
    record = _complete_record(entry.path)
    assert record is not None and "mesh.ply" in record["files"]
    assert f"{ASSET_DIR}/synthetic_box.xml" in record["files"]


def test_a_session_exported_then_added_is_stored_with_mesh_and_asset(session, tmp_path):
    export_session(session, tmp_path / "out", **QUICK)
    lib = ModelLibrary(tmp_path / "lib")
    entry_id = add_session_model(lib.root, session)
    assert_entry_holds_the_export(lib, entry_id, tmp_path / "out")


def test_a_session_added_then_exported_gets_mesh_and_asset_on_the_same_entry(session, tmp_path):
    lib = ModelLibrary(tmp_path / "lib")
    entry_id = add_session_model(lib.root, session)
    assert lib.get(entry_id).mesh_path is None
    export_session(session, tmp_path / "out", **QUICK)
    assert add_session_model(lib.root, session) == entry_id  # the same entry, now with the export
    assert_entry_holds_the_export(lib, entry_id, tmp_path / "out")
    assert len(lib) == 1


def test_the_export_finds_the_entry_the_acquisition_made(session, tmp_path):
    lib = ModelLibrary(tmp_path / "lib")
    entry_id = add_session_model(lib.root, session)
    # what the orchestrator's journal says after storing the model
    (session / "journal.json").write_text(json.dumps({"library_entry": entry_id, "decisions": [
        {"what": "model added to the library", "entry": entry_id, "library": str(lib.root)}]}))
    assert attach_session_export(session) is None  # nothing exported yet
    export_session(session, tmp_path / "out", **QUICK)
    assert attach_session_export(session) == entry_id
    assert_entry_holds_the_export(lib, entry_id, tmp_path / "out")
    # a second export replaces the first one's files
    export_session(session, tmp_path / "out2", **{**QUICK, "formats": ("stl",)})
    assert attach_session_export(session) == entry_id
    asset = ModelLibrary(lib.root).get(entry_id).asset_path
    assert not (asset / "synthetic_box.xml").exists() and (asset / "synthetic_box.stl").is_file()
    assert np.isfinite(json.loads((asset / "export.json").read_text())["seconds"])

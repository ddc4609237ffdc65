"""The model library: acquired models as files indexed in SQLite, searchable by a partial view.

- ``ModelLibrary(root)``: ``add``, ``attach``, ``list``, ``get``, ``export``, ``delete``, ``find`` (store.py; crash
  rule there)
- ``add_session_model(library_root, session_dir)``: what the orchestrator calls at the end of a run;
  ``attach_session_export(session_dir)``: the export's mesh and asset stored with that entry afterwards
- ``find`` ranks models for a partial view: GOOD shortlist, then registration fitness (matching.py)

See docs/library.md.
"""

from services.library.errors import BadModelInput, LibraryError, ModelNotFound, UnacceptedModel
from services.library.matching import FindConfig, Match
from services.library.metadata import ModelMetadata
from services.library.session import add_session_model, attach_session_export, session_metadata
from services.library.store import ModelEntry, ModelLibrary, ReconcileReport

__all__ = ["BadModelInput", "FindConfig", "LibraryError", "Match", "ModelEntry", "ModelLibrary", "ModelMetadata",
           "ModelNotFound", "ReconcileReport", "UnacceptedModel", "add_session_model", "attach_session_export",
           "session_metadata"]

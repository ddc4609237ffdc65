"""Store the model of a finished acquisition: what the orchestrator calls at the end of a run.

It reads what the session folder already holds (``model.ply``, ``session.json``, ``report.json`` written
either by the orchestrator or by ``objscan reconstruct``) and turns it into a library entry. Calling it again
for the same session and the same model file returns the existing entry instead of storing a copy, so an
orchestrator that crashed right after adding and resumed does not duplicate the model.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from common.atomic import sha256_file
from common.session_folder import MODEL_FILE, REPORT_FILE, SESSION_FILE
from services.library.errors import BadModelInput
from services.library.metadata import ModelMetadata
from services.library.store import MESH_FILE, ModelEntry, ModelLibrary

#: Where the export says which folder it wrote (services/export/pipeline.py writes it).
OBJECT_FRAME_FILE = "object_frame.json"
ACCURACY_KEYS = ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")


def session_metadata(session_dir: str | Path) -> ModelMetadata:
    """Metadata for the model of ``session_dir``: object, date, session, configuration, quality figures."""
    session = Path(session_dir).resolve()
    model = session / MODEL_FILE
    if not model.is_file():
        raise BadModelInput(f"{session} holds no model.ply (did the acquisition finish?)", code="no_model",
                            detail={"session": str(session)})
    info = _json(session / SESSION_FILE)
    report = _json(session / REPORT_FILE)
    journal = _json(session / "journal.json")
    figures = report.get("model_figures") or (report.get("model") if isinstance(report.get("model"), dict) else {})
    quality: dict[str, Any] = {"points": report.get("points", figures.get("points"))}
    accepted = report.get("accepted", figures.get("accepted"))  # reports written before the verdict have none
    if accepted is not None:
        quality["accepted"] = bool(accepted)
        quality["why"] = report.get("why", figures.get("why", ""))
    for key in ("configuration", "reason", "loop_closure", "consistency", "voxel_mm"):
        if key in figures:
            quality[key] = figures[key]
    edges = figures.get("edges") or []
    fits = [float(e["fitness"]) for e in edges if isinstance(e, dict) and "fitness" in e]
    if fits:
        quality["edge_fitness_min"] = min(fits)
        quality["edge_fitness_mean"] = sum(fits) / len(fits)
    accuracy = report.get("accuracy") or {}
    quality.update({k: accuracy[k] for k in ACCURACY_KEYS if k in accuracy})
    if "seconds_total" in report:
        quality["seconds_total"] = report["seconds_total"]
    config = info.get("config") or journal.get("config") or {}
    name = info.get("object") or config.get("object") or report.get("object") or session.name
    return ModelMetadata(
        object_name=str(Path(str(name)).stem) if "/" in str(name) else str(name),
        created=model.stat().st_mtime, session=str(session), configuration=figures.get("configuration"),
        quality={k: v for k, v in quality.items() if v is not None}, source="session",
        extra={"profile": info.get("profile", config.get("profile")), "seed": info.get("seed", config.get("seed")),
               "views": len(info.get("views", [])), "model_sha256": sha256_file(model)})


def session_export(session_dir: str | Path) -> tuple[Path | None, Path | None]:
    """The session's exported mesh (``mesh.ply``, model frame) and asset folder, each None when not there.

    The export writes ``SESSION/mesh.ply`` and names its output folder in ``SESSION/object_frame.json``
    (``export``); a folder that has moved since, or holds no ``export.json``, is not an asset.
    """
    session = Path(session_dir)
    mesh = session / MESH_FILE
    frame = _json(session / OBJECT_FRAME_FILE)
    asset = Path(frame["export"]) if isinstance(frame.get("export"), str) else None
    if asset is not None and not asset.is_absolute():
        asset = session / asset
    return (mesh if mesh.is_file() else None,
            asset if asset is not None and (asset / "export.json").is_file() else None)


def add_session_model(library_root: str | Path, session_dir: str | Path, *, allow_unaccepted: bool = False) -> str:
    """Add ``session_dir/model.ply`` (with the export's mesh and asset when the session has them) to the
    library; returns its id.

    Idempotent per (session, model file): a second call returns the id stored the first time, after storing
    with it the mesh and asset the session gained since (exported after it was added). A model whose
    report says ``accepted: false`` is refused (``UnacceptedModel``) unless ``allow_unaccepted``.
    """
    lib = ModelLibrary(library_root)
    meta = session_metadata(session_dir)
    mesh, asset = session_export(session_dir)
    for entry in lib.list(meta.object_name):
        if entry.metadata.session == meta.session and \
                entry.metadata.extra.get("model_sha256") == meta.extra["model_sha256"]:
            _attach_newer(lib, entry, mesh, asset)
            return entry.id
    return lib.add(Path(session_dir) / MODEL_FILE, meta, mesh=mesh, asset=asset,
                   allow_unaccepted=allow_unaccepted)


def session_library_entry(session_dir: str | Path) -> tuple[Path, str] | None:
    """(library root, entry id) the acquisition stored this session's model in, from its journal; else None."""
    journal = _json(Path(session_dir) / "journal.json")
    entry = journal.get("library_entry")
    if not entry:
        return None
    for d in reversed(journal.get("decisions") or []):
        if isinstance(d, dict) and d.get("entry") == entry and d.get("library"):
            return Path(d["library"]), str(entry)
    return None


def attach_session_export(session_dir: str | Path) -> str | None:
    """Store the session's export (mesh and asset) with the library entry its acquisition made; its id, or
    None when the acquisition stored no entry (no library, an unaccepted model) or the session has no export.
    """
    found = session_library_entry(session_dir)
    mesh, asset = session_export(session_dir)
    if found is None or (mesh is None and asset is None):
        return None
    root, entry_id = found
    lib = ModelLibrary(root)
    entry = lib.get(entry_id)
    _attach_newer(lib, entry, mesh, asset)
    return entry.id


def _attach_newer(lib: ModelLibrary, entry: ModelEntry, mesh: Path | None, asset: Path | None) -> None:
    """Attach what the entry lacks or holds in an older version (by content: mesh digest, asset figures)."""
    new_mesh = mesh if mesh is not None and (
        entry.mesh_path is None or sha256_file(entry.mesh_path) != sha256_file(mesh)) else None
    new_asset = asset if asset is not None and (
        entry.asset_path is None or not (entry.asset_path / "export.json").is_file()
        or sha256_file(entry.asset_path / "export.json") != sha256_file(asset / "export.json")) else None
    if new_mesh is not None or new_asset is not None:
        lib.attach(entry.id, mesh=new_mesh, asset=new_asset)


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise BadModelInput(f"{path} is not valid JSON: {exc}", code="bad_session",
                            detail={"path": str(path)}) from None
    return data if isinstance(data, dict) else {}

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
from services.library.errors import BadModelInput
from services.library.metadata import ModelMetadata
from services.library.store import ModelLibrary

ACCURACY_KEYS = ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")


def session_metadata(session_dir: str | Path) -> ModelMetadata:
    """Metadata for the model of ``session_dir``: object, date, session, configuration, quality figures."""
    session = Path(session_dir).resolve()
    model = session / "model.ply"
    if not model.is_file():
        raise BadModelInput(f"{session} holds no model.ply (did the acquisition finish?)", code="no_model",
                            detail={"session": str(session)})
    info = _json(session / "session.json")
    report = _json(session / "report.json")
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


def add_session_model(library_root: str | Path, session_dir: str | Path, *, allow_unaccepted: bool = False) -> str:
    """Add ``session_dir/model.ply`` (with ``mesh.ply`` when the session has one) to the library; returns its id.

    Idempotent per (session, model file): a second call returns the id stored the first time. A model whose
    report says ``accepted: false`` is refused (``UnacceptedModel``) unless ``allow_unaccepted``.
    """
    lib = ModelLibrary(library_root)
    meta = session_metadata(session_dir)
    for entry in lib.list(meta.object_name):
        if entry.metadata.session == meta.session and \
                entry.metadata.extra.get("model_sha256") == meta.extra["model_sha256"]:
            return entry.id
    session = Path(session_dir)
    mesh = session / "mesh.ply"
    return lib.add(session / "model.ply", meta, mesh=mesh if mesh.is_file() else None,
                   allow_unaccepted=allow_unaccepted)


def _json(path: Path) -> dict[str, Any]:
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise BadModelInput(f"{path} is not valid JSON: {exc}", code="bad_session",
                            detail={"path": str(path)}) from None
    return data if isinstance(data, dict) else {}

"""The model library: models as files, indexed in SQLite, consistent across crashes.

Layout under ``root``::

    library.json                 the marker: this folder is an objscan library (written when it is created)
    index.sqlite                 one row per model (id, object, date, session, configuration, metadata JSON)
    .lock                        fcntl lock: one writer (or reconciler) at a time, across processes
    entries/<id>/model.ply       the model point cloud (binary PLY, colors and normals when known)
    entries/<id>/mesh.ply        optional surface mesh (the export's closed mesh, in the model's frame)
    entries/<id>/asset/          optional simulation asset (the export's folder: MJCF, URDF, GLB, ...)
    entries/<id>/descriptors.npz GOOD of the whole model and of its synthetic partial views (for ``find``)
    entries/<id>/metadata.json   written last: id, metadata, and the size + SHA-256 of every other file
    .staging/<id>.<pid>/         an ``add`` in progress
    .trash/<id>.<pid>/           a ``delete`` in progress

Crash safety (the rule, tested in tests/library/test_crash_safety.py):

- ``add`` writes every file into ``.staging``, fsyncs them and the folder, renames the folder into
  ``entries/`` (atomic on POSIX: the *commit point* of an add), fsyncs ``entries/``, and only then inserts
  the index row in a transaction.
- ``delete`` renames the entry into ``.trash`` (its commit point), deletes the row, then removes the files.
- On open the library *reconciles* (under the lock, so never against a live writer): it removes everything
  in ``.staging`` and ``.trash``; drops index rows whose entry folder or model file is missing; and for
  every entry folder without a row, indexes it if it is complete (``metadata.json`` parses, names this id,
  and every file it lists is there with the recorded size and SHA-256) or removes it if not.

Ownership (a library never deletes what it did not create): a
folder becomes a library only when it is absent or empty (then ``library.json``
marks it), or already is one (the marker, or an older library's ``index.sqlite`` with our schema, which
gets the marker). Anything else is refused with ``not_a_library`` before a single file is touched. The
tidy-up removes only names the library itself creates (``<entry id>`` and ``<entry id>.<pid>``); anything
else found under ``entries/``, ``.staging/``, ``.trash/`` is left alone and listed in ``foreign``.

- ``attach`` (a mesh or an asset for an entry that exists, e.g. exported after the scan stored it) writes
  the new files into the entry under temporary names and renames each into place (a reader never sees a
  half file), then replaces ``metadata.json`` (write, fsync, rename: its commit point) and updates the row.
  A crash before the metadata leaves files the entry does not list (harmless, replaced by the next attach).

So a crash before the rename leaves nothing (the add never happened); a crash after it leaves an entry that
the next open indexes (the add happened; only the index lagged); there is never an orphan folder nor a row
without its files. An exception (rather than a kill) inside ``add`` rolls back at once.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import json
import logging
import os
import re
import secrets
import shutil
import sqlite3
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import open3d as o3d

from common.atomic import atomic_write_bytes, atomic_write_with, fsync_dir, fsync_file, sha256_file, write_synced
from common.messages import PointCloud
from common.session_folder import MODEL_FILE, json_default
from services.library.descriptors import DescriptorConfig, check_xyz, model_descriptors
from services.library.errors import BadModelInput, LibraryError, ModelNotFound, UnacceptedModel
from services.library.matching import find as find_matches
from services.library.metadata import ModelMetadata, slug
from services.registration.api import CloudError, to_o3d

log = logging.getLogger("objscan.library")

INDEX = "index.sqlite"
ENTRIES = "entries"
STAGING = ".staging"
TRASH = ".trash"
LOCK = ".lock"
MESH_FILE = "mesh.ply"
ASSET_DIR = "asset"
DESCRIPTORS_FILE = "descriptors.npz"
METADATA_FILE = "metadata.json"
MARKER = "library.json"
SCHEMA_VERSION = 1
ENTRY_ID = re.compile(r"^[a-z0-9][a-z0-9-]{0,39}-\d{8}-\d{6}-[0-9a-f]{6}$")
"""What ``add`` names an entry (slug, local time, 3 random bytes): the only names the tidy-up may remove."""
WORK_NAME = re.compile(r"^(?P<id>[a-z0-9][a-z0-9-]{0,39}-\d{8}-\d{6}-[0-9a-f]{6})\.\d+$")
"""``<entry id>.<pid>``: an add (``.staging``) or delete (``.trash``) in progress."""

#: The named points an ``add`` or ``delete`` passes (``ModelLibrary._passed``): the crash rule is stated, and
#: checked, at each of them.
ADD_STAGES = ("staging_created", "files_written", "metadata_written", "renamed", "row_inserted", "committed")
DELETE_STAGES = ("trashed", "row_deleted", "committed")

ModelInput = str | Path | PointCloud | o3d.geometry.PointCloud | np.ndarray


@dataclass
class ModelEntry:
    """One stored model as the index knows it; paths point into the library (read-only for callers)."""

    id: str
    metadata: ModelMetadata
    path: Path
    points: int

    @property
    def model_path(self) -> Path:
        return self.path / MODEL_FILE

    @property
    def mesh_path(self) -> Path | None:
        p = self.path / MESH_FILE
        return p if p.is_file() else None

    @property
    def asset_path(self) -> Path | None:
        p = self.path / ASSET_DIR
        return p if p.is_dir() else None

    def summary(self) -> dict[str, Any]:
        """The short JSON-able form ``models list`` prints."""
        q = self.metadata.quality
        return {"id": self.id, "object": self.metadata.object_name,
                "created": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.metadata.created)),
                "points": self.points, "configuration": self.metadata.configuration,
                "chamfer_mm": q.get("chamfer_mm"), "session": self.metadata.session,
                "mesh": self.mesh_path is not None, "asset": self.asset_path is not None}


@dataclass
class ReconcileReport:
    """What opening the library repaired (all empty on a clean library)."""

    removed_staging: list[str] = field(default_factory=list)
    removed_trash: list[str] = field(default_factory=list)
    dropped_rows: list[str] = field(default_factory=list)
    indexed: list[str] = field(default_factory=list)
    removed_incomplete: list[str] = field(default_factory=list)
    foreign: list[str] = field(default_factory=list)  # not ours: left where they are

    def changed(self) -> bool:
        return any((self.removed_staging, self.removed_trash, self.dropped_rows, self.indexed,
                    self.removed_incomplete))


class ModelLibrary:
    """A folder of models with a SQLite index; see the module doc for the layout and the crash rule."""

    def __init__(self, root: str | Path, *, descriptor_config: DescriptorConfig | None = None):
        self.root = Path(root)
        self.descriptor_config = descriptor_config or DescriptorConfig()
        _claim(self.root)
        try:
            for sub in (ENTRIES, STAGING, TRASH):
                (self.root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise LibraryError(f"cannot create library folder {self.root}: {exc}") from None
        with self._locked():
            self._init_schema()
            self.last_reconcile = self._reconcile()
        if self.last_reconcile.changed():
            log.warning("library %s repaired on open: %s", self.root, self.last_reconcile)

    # ------------------------------------------------------------------------------------------ public
    def add(self, model_ply: ModelInput, metadata: ModelMetadata | dict[str, Any], *,
            mesh: str | Path | o3d.geometry.TriangleMesh | None = None, asset: str | Path | None = None,
            allow_unaccepted: bool = False) -> str:
        """Store a model (a PLY path, a wire ``PointCloud``, an Open3D cloud or an (N, 3) array); returns its id.

        The GOOD descriptors are computed here (whole model + synthetic views) and the whole-model one is
        copied into ``metadata.descriptor``. Raises ``BadModelInput`` for an empty, NaN or unreadable model,
        and ``UnacceptedModel`` for one whose ``metadata.quality["accepted"]`` is ``False`` (the dynamic stage
        did not accept it) unless ``allow_unaccepted``: a wrong model in the library would be matched against.
        ``asset``: a folder (the export's) copied as the entry's ``asset/``.
        """
        meta = metadata if isinstance(metadata, ModelMetadata) else ModelMetadata.from_dict(metadata)
        meta.validate()
        if meta.quality.get("accepted") is False and not allow_unaccepted:
            raise UnacceptedModel(f"model of {meta.object_name!r} was not accepted "
                                  f"({meta.quality.get('why') or 'see its report'}); pass allow_unaccepted=True "
                                  "to store it anyway",
                                  detail={"session": meta.session, "why": meta.quality.get("why")})
        pcd = _load_cloud(model_ply)
        mesh_obj = _load_mesh(mesh) if mesh is not None else None
        desc = model_descriptors(np.asarray(pcd.points), self.descriptor_config)
        meta.descriptor = {"kind": "GOOD", "n_bins": desc["n_bins"], "whole": desc["whole"].round(8).tolist(),
                           "synthetic_views": int(desc["views"].shape[0])}
        entry_id = f"{slug(meta.object_name)}-{time.strftime('%Y%m%d-%H%M%S', time.localtime(meta.created))}-" \
                   f"{secrets.token_hex(3)}"
        with self._locked():
            stage = self.root / STAGING / f"{entry_id}.{os.getpid()}"
            final = self.root / ENTRIES / entry_id
            try:
                stage.mkdir()
                self._passed("staging_created")
                files = {MODEL_FILE: _write_cloud(stage / MODEL_FILE, pcd),
                         DESCRIPTORS_FILE: _write_npz(stage / DESCRIPTORS_FILE, desc)}
                if mesh_obj is not None:
                    files[MESH_FILE] = _write_mesh(stage / MESH_FILE, mesh_obj)
                if asset is not None:
                    files.update(_copy_asset(Path(asset), stage / ASSET_DIR))
                self._passed("files_written")
                record = {"id": entry_id, "points": len(pcd.points), "files": files, "metadata": meta.to_dict()}
                _write_synced(stage / METADATA_FILE, json.dumps(record, indent=2, default=json_default).encode())
                fsync_dir(stage)
                self._passed("metadata_written")
                os.rename(stage, final)
                fsync_dir(final.parent)
                fsync_dir(stage.parent)
            except BaseException:
                shutil.rmtree(stage, ignore_errors=True)
                raise
            try:
                self._passed("renamed")
                with self._transaction() as db:
                    db.execute("INSERT INTO models VALUES (?, ?, ?, ?, ?, ?, ?, ?)", _row(record))
                    self._passed("row_inserted")
                self._passed("committed")
            except BaseException:
                # roll back a committed-on-disk entry the caller never got an id for; the row (if the
                # failure came after commit) goes too, so either both exist or neither does
                self._remove_entry(entry_id, mark_stages=False)
                raise
        return entry_id

    def attach(self, entry_id: str, *, mesh: str | Path | o3d.geometry.TriangleMesh | None = None,
               asset: str | Path | None = None) -> ModelEntry:
        """Store ``mesh`` (as ``mesh.ply``) and/or the folder ``asset`` (as ``asset/``) with an existing entry.

        For a model exported after it was stored (``objscan scan --export``: the acquisition adds the model,
        the export follows). What was attached before is replaced. Crash rule in the module doc.
        """
        mesh_obj = _load_mesh(mesh) if mesh is not None else None
        if asset is not None and not Path(asset).is_dir():
            raise BadModelInput(f"asset {asset} is not a folder", detail={"asset": str(asset)})
        with self._locked():
            full = self._row_for(entry_id)[0]
            folder = self.root / ENTRIES / full
            record = json.loads((folder / METADATA_FILE).read_text())
            files = dict(record["files"])
            tag = f".{os.getpid()}.tmp"
            if mesh_obj is not None:
                tmp = folder / f".{os.getpid()}.tmp.{MESH_FILE}"  # Open3D writes by the extension
                files[MESH_FILE] = _write_mesh(tmp, mesh_obj)
                os.replace(tmp, folder / MESH_FILE)
            if asset is not None:
                tmp = folder / (ASSET_DIR + tag)
                shutil.rmtree(tmp, ignore_errors=True)
                copied = _copy_asset(Path(asset), tmp)
                old = folder / (ASSET_DIR + f".{os.getpid()}.old")
                if (folder / ASSET_DIR).exists():
                    os.rename(folder / ASSET_DIR, old)
                os.rename(tmp, folder / ASSET_DIR)
                shutil.rmtree(old, ignore_errors=True)
                files = {k: v for k, v in files.items() if not k.startswith(ASSET_DIR + "/")} | {
                    ASSET_DIR + k[len(tmp.name):]: v for k, v in copied.items()}
            fsync_dir(folder)
            record["files"] = files
            atomic_write_bytes(folder / METADATA_FILE, json.dumps(record, indent=2, default=json_default).encode())
            with self._transaction() as db:
                db.execute("UPDATE models SET has_mesh = ? WHERE id = ?", (int(MESH_FILE in files), full))
        return self.get(full)

    def list(self, object_name: str | None = None) -> list[ModelEntry]:
        """Every stored model (oldest first), optionally only those of one object name."""
        sql = "SELECT id, metadata, points FROM models"
        args: tuple = ()
        if object_name is not None:
            sql += " WHERE object_name = ?"
            args = (object_name,)
        with self._connect() as db:
            rows = db.execute(sql + " ORDER BY created, id", args).fetchall()
        return [self._entry(*r) for r in rows]

    def get(self, entry_id: str) -> ModelEntry:
        """The entry of ``entry_id`` (a unique prefix is enough); ``ModelNotFound`` otherwise."""
        return self._entry(*self._row_for(entry_id))

    def export(self, entry_id: str, dest: str | Path) -> list[Path]:
        """Copy a model out of the library; returns the files written.

        ``dest`` ending in ``.ply``: the model PLY is written there and its metadata beside it
        (``<stem>.json``). Otherwise ``dest`` is a folder that receives ``model.ply``, ``metadata.json``
        and ``mesh.ply`` when there is one. Each copy goes through a temporary name (no half files).
        """
        entry = self.get(entry_id)
        dest = Path(dest)
        pairs: list[tuple[Path, Path]]
        if dest.suffix.lower() == ".ply":
            pairs = [(entry.model_path, dest), (entry.path / METADATA_FILE, dest.with_suffix(".json"))]
            if entry.mesh_path is not None:
                pairs.append((entry.mesh_path, dest.with_name(f"{dest.stem}_mesh.ply")))
        else:
            pairs = [(entry.path / name, dest / name) for name in (MODEL_FILE, METADATA_FILE, MESH_FILE)
                     if (entry.path / name).is_file()]
        out = []
        for src, dst in pairs:
            try:
                atomic_write_with(dst, lambda tmp, src=src: shutil.copyfile(src, tmp))
            except OSError as exc:
                raise LibraryError(f"cannot export to {dst}: {exc}", code="io_error") from None
            out.append(dst)
        return out

    def delete(self, entry_id: str) -> str:
        """Remove a model (files and row); returns the full id deleted."""
        with self._locked():
            full = self._row_for(entry_id)[0]
            try:
                self._remove_entry(full)
            except BaseException:
                # past the trash rename the delete has happened: finish it so files and index agree now
                self._reconcile()
                raise
        return full

    def find(self, cloud_xyz: np.ndarray | PointCloud | str | Path, top_k: int = 3, *,
             rgb: np.ndarray | None = None, config: Any = None) -> list:
        """Best-matching stored models for a (partial) view, best first: ``[Match(id, score, detail)]``.

        See ``services.library.matching.find`` for how (GOOD shortlist, then registration fitness).
        """
        return find_matches(self, cloud_xyz, top_k, rgb=rgb, config=config)

    def descriptors(self, entry_id: str) -> dict[str, np.ndarray]:
        """The stored GOOD descriptors of a model: ``whole`` (D,) and ``views`` (V, D)."""
        entry = self.get(entry_id)
        try:
            with np.load(entry.path / DESCRIPTORS_FILE) as z:
                return {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise LibraryError(f"descriptors of {entry.id} are unreadable: {exc}") from None

    def load_cloud(self, entry_id: str) -> o3d.geometry.PointCloud:
        """The stored model as an Open3D cloud (colors and normals when it has them)."""
        return o3d.io.read_point_cloud(str(self.get(entry_id).model_path))

    def __len__(self) -> int:
        with self._connect() as db:
            return int(db.execute("SELECT COUNT(*) FROM models").fetchone()[0])

    # ------------------------------------------------------------------------------------------ internals
    def _passed(self, stage: str) -> None:
        """An add or delete has reached ``stage`` (one of ``ADD_STAGES`` / ``DELETE_STAGES``): the points
        where the crash rule says what a crash leaves. Nothing to do here; named so the rule can be checked
        at each point."""

    def _entry(self, entry_id: str, metadata_json: str, points: int) -> ModelEntry:
        return ModelEntry(id=entry_id, metadata=ModelMetadata.from_dict(json.loads(metadata_json)),
                          path=self.root / ENTRIES / entry_id, points=int(points))

    def _row_for(self, entry_id: str) -> tuple[str, str, int]:
        if not isinstance(entry_id, str) or not entry_id:
            raise ModelNotFound("a model id is needed", detail={"id": entry_id})
        with self._connect() as db:
            rows = db.execute("SELECT id, metadata, points FROM models WHERE id = ?", (entry_id,)).fetchall()
            if not rows:
                pattern = entry_id.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"
                rows = db.execute("SELECT id, metadata, points FROM models WHERE id LIKE ? ESCAPE '\\'",
                                  (pattern,)).fetchall()
        if not rows:
            raise ModelNotFound(f"no model {entry_id!r} in {self.root}", detail={"id": entry_id})
        if len(rows) > 1:
            raise ModelNotFound(f"{entry_id!r} is ambiguous", code="ambiguous_id",
                                detail={"id": entry_id, "matches": sorted(r[0] for r in rows)[:10]})
        return rows[0]

    def _remove_entry(self, entry_id: str, *, mark_stages: bool = True) -> None:
        """Trash the folder (commit point), delete the row, then the files; the caller holds the lock.
        ``mark_stages`` is False when an add rolls back (its stages are not a delete's)."""
        passed = self._passed if mark_stages else (lambda _stage: None)
        src = self.root / ENTRIES / entry_id
        trash = self.root / TRASH / f"{entry_id}.{os.getpid()}"
        if src.exists():
            os.rename(src, trash)
            fsync_dir(src.parent)
        passed("trashed")
        with self._transaction() as db:
            db.execute("DELETE FROM models WHERE id = ?", (entry_id,))
            passed("row_deleted")
        passed("committed")
        shutil.rmtree(trash, ignore_errors=True)

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        try:
            fh = open(self.root / LOCK, "a+")  # noqa: SIM115 - held for the with-block
        except OSError as exc:
            raise LibraryError(f"cannot open the library lock in {self.root}: {exc}") from None
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
            fh.close()

    @contextlib.contextmanager
    def _connect(self) -> Iterator[sqlite3.Connection]:
        try:
            db = sqlite3.connect(self.root / INDEX, timeout=30.0, isolation_level=None)
        except sqlite3.Error as exc:
            raise LibraryError(f"cannot open the index of {self.root}: {exc}") from None
        try:
            db.execute("PRAGMA synchronous = FULL")
            yield db
        except sqlite3.DatabaseError as exc:
            raise LibraryError(f"index of {self.root} is unusable: {exc}") from None
        finally:
            db.close()

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
            except BaseException:
                db.execute("ROLLBACK")
                raise
            db.execute("COMMIT")

    def _init_schema(self) -> None:
        with self._connect() as db:
            version = int(db.execute("PRAGMA user_version").fetchone()[0])
            if version > SCHEMA_VERSION:
                raise LibraryError(f"{self.root} was written by a newer objscan (index schema {version})",
                                   code="library_version", detail={"schema": version})
            db.execute("""CREATE TABLE IF NOT EXISTS models (
                id TEXT PRIMARY KEY, object_name TEXT NOT NULL, created REAL NOT NULL, session TEXT,
                configuration TEXT, points INTEGER NOT NULL, has_mesh INTEGER NOT NULL, metadata TEXT NOT NULL)""")
            db.execute("CREATE INDEX IF NOT EXISTS models_object ON models(object_name)")
            db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    def _reconcile(self) -> ReconcileReport:
        """Bring files and index back into agreement after a crash (rule in the module doc)."""
        rep = ReconcileReport()
        for sub, found in ((STAGING, rep.removed_staging), (TRASH, rep.removed_trash)):
            for d in sorted((self.root / sub).iterdir()):
                if not (d.is_dir() and not d.is_symlink() and WORK_NAME.match(d.name)):
                    rep.foreign.append(f"{sub}/{d.name}")
                    continue
                shutil.rmtree(d)
                found.append(d.name)
        entries = self.root / ENTRIES
        with self._connect() as db:
            indexed = {r[0] for r in db.execute("SELECT id FROM models")}
        on_disk = set()
        for d in entries.iterdir():
            if d.is_dir() and not d.is_symlink() and ENTRY_ID.match(d.name):
                on_disk.add(d.name)
            else:
                rep.foreign.append(f"{ENTRIES}/{d.name}")
        missing = sorted(i for i in indexed if i not in on_disk or not (entries / i / MODEL_FILE).is_file())
        if missing:
            with self._transaction() as db:
                db.executemany("DELETE FROM models WHERE id = ?", [(i,) for i in missing])
            rep.dropped_rows.extend(missing)
            for i in missing:
                if i in on_disk:  # an entry folder of ours without its model file
                    shutil.rmtree(entries / i, ignore_errors=True)
        for name in sorted(on_disk - indexed):
            record = _complete_record(entries / name)
            if record is None:
                shutil.rmtree(entries / name)
                rep.removed_incomplete.append(name)
                continue
            with self._transaction() as db:
                db.execute("INSERT INTO models VALUES (?, ?, ?, ?, ?, ?, ?, ?)", _row(record))
            rep.indexed.append(name)
        return rep


# ---------------------------------------------------------------------------------------------- helpers

def _claim(root: Path) -> None:
    """Make sure ``root`` is (or becomes) a library, refusing any other folder before touching it."""
    marker = root / MARKER
    if marker.is_file():
        try:
            data = json.loads(marker.read_text())
        except (OSError, json.JSONDecodeError):
            data = None
        version = data.get("objscan_library") if isinstance(data, dict) else None
        if isinstance(version, bool) or not isinstance(version, int) or version < 1:
            raise LibraryError(f"{marker} is not an objscan library marker", code="not_a_library",
                               detail={"path": str(root)})
        return
    if root.exists() and not root.is_dir():
        raise LibraryError(f"{root} is not a folder", code="not_a_library", detail={"path": str(root)})
    if root.is_dir() and any(root.iterdir()) and not _is_older_library(root):
        raise LibraryError(f"{root} is not empty and is not an objscan library: refusing to use it (a library "
                           f"tidies its folders on open)", code="not_a_library",
                           detail={"path": str(root), "found": sorted(p.name for p in root.iterdir())[:10]})
    try:
        root.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(marker, json.dumps({"objscan_library": SCHEMA_VERSION, "created": time.time()}).encode())
    except OSError as exc:
        raise LibraryError(f"cannot create library folder {root}: {exc}") from None


def _is_older_library(root: Path) -> bool:
    """A library written before the marker existed: its index holds our table at a schema we know."""
    index = root / INDEX
    if not index.is_file():
        return False
    try:
        db = sqlite3.connect(f"file:{index}?mode=ro", uri=True)
        try:
            version = int(db.execute("PRAGMA user_version").fetchone()[0])
            has_table = db.execute("SELECT 1 FROM sqlite_master WHERE type='table' AND name='models'").fetchone()
        finally:
            db.close()
    except sqlite3.Error:
        return False
    return 1 <= version <= SCHEMA_VERSION and has_table is not None


def _row(record: dict[str, Any]) -> tuple:
    meta = record["metadata"]
    return (record["id"], meta["object_name"], float(meta["created"]), meta.get("session"),
            meta.get("configuration"), int(record["points"]), int(MESH_FILE in record["files"]),
            json.dumps(meta, default=json_default))


def _complete_record(folder: Path) -> dict[str, Any] | None:
    """The metadata record of an entry folder if every file it lists is intact, else None."""
    try:
        record = json.loads((folder / METADATA_FILE).read_text())
        if record.get("id") != folder.name or MODEL_FILE not in record.get("files", {}):
            return None
        ModelMetadata.from_dict(record["metadata"])
        for name, info in record["files"].items():
            p = folder / name
            if not p.is_file() or p.stat().st_size != int(info["bytes"]) or sha256_file(p) != info["sha256"]:
                return None
        return record
    except (OSError, ValueError, KeyError, TypeError, BadModelInput):
        return None


def _write_synced(path: Path, data: bytes) -> dict[str, Any]:
    """Write a staged file and return its record (size, digest) for the entry's metadata."""
    write_synced(path, data)
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def _fsync_file(path: Path) -> dict[str, Any]:
    """fsync a staged file another library wrote (Open3D) and return its record (size, digest)."""
    fsync_file(path)
    return {"bytes": path.stat().st_size, "sha256": sha256_file(path)}


def _write_cloud(path: Path, pcd: o3d.geometry.PointCloud) -> dict[str, Any]:
    if not o3d.io.write_point_cloud(str(path), pcd, write_ascii=False):
        raise LibraryError(f"could not write {path}", code="io_error")
    return _fsync_file(path)


def _write_mesh(path: Path, mesh: o3d.geometry.TriangleMesh) -> dict[str, Any]:
    if not o3d.io.write_triangle_mesh(str(path), mesh, write_ascii=False):
        raise LibraryError(f"could not write {path}", code="io_error")
    return _fsync_file(path)


def _copy_asset(src: Path, dest: Path) -> dict[str, dict[str, Any]]:
    """Copy the asset folder ``src`` to ``dest`` (synced); the records of its files, named ``<dest name>/...``."""
    if not src.is_dir():
        raise BadModelInput(f"asset {src} is not a folder", detail={"asset": str(src)})
    try:
        shutil.copytree(src, dest)
    except OSError as exc:
        raise LibraryError(f"cannot copy the asset {src}: {exc}", code="io_error") from None
    out = {}
    for p in sorted(dest.rglob("*")):
        if p.is_file():
            out[f"{dest.name}/{p.relative_to(dest).as_posix()}"] = _fsync_file(p)
    for d in sorted({p.parent for p in dest.rglob("*")} | {dest}, key=lambda q: -len(q.parts)):
        fsync_dir(d)
    return out


def _write_npz(path: Path, desc: dict[str, Any]) -> dict[str, Any]:
    buf = io.BytesIO()
    np.savez(buf, whole=np.asarray(desc["whole"]), views=np.asarray(desc["views"]),
             n_bins=np.asarray(desc["n_bins"]))
    return _write_synced(path, buf.getvalue())


def _load_cloud(model: ModelInput) -> o3d.geometry.PointCloud:
    """Any accepted model input as a validated Open3D cloud (finite, non-empty)."""
    if isinstance(model, str | Path):
        p = Path(model)
        if not p.is_file():
            raise BadModelInput(f"{p} does not exist", code="io_error", detail={"path": str(p)})
        pcd = o3d.io.read_point_cloud(str(p))
    elif isinstance(model, PointCloud):
        try:
            pcd = to_o3d(model)
        except CloudError as exc:
            raise BadModelInput(exc.message, detail=exc.detail) from None
    elif isinstance(model, o3d.geometry.PointCloud):
        pcd = o3d.geometry.PointCloud(model)
    elif isinstance(model, np.ndarray):
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(check_xyz(model, "model")))
    else:
        raise BadModelInput(f"cannot store a {type(model).__name__} as a model", detail={"type": type(model).__name__})
    check_xyz(np.asarray(pcd.points), "model")
    return pcd


def _load_mesh(mesh: str | Path | o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    m = mesh if isinstance(mesh, o3d.geometry.TriangleMesh) else o3d.io.read_triangle_mesh(str(mesh))
    if len(m.triangles) == 0:
        raise BadModelInput(f"mesh {mesh} has no triangles", detail={"mesh": str(mesh)})
    if not np.isfinite(np.asarray(m.vertices)).all():
        raise BadModelInput("mesh vertices contain NaN or inf")
    return m




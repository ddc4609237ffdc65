"""ModelLibrary storage: add / list / get / export / delete round trips, id lookup, typed errors."""

from __future__ import annotations

import json
import threading

import numpy as np
import open3d as o3d
import pytest

from services.library import BadModelInput, ModelLibrary, ModelMetadata, ModelNotFound
from services.library.descriptors import describe
from services.library.store import ENTRIES, STAGING
from tests.library.helpers import FAST_DESCRIPTORS, box_surface


@pytest.fixture
def lib(tmp_path):
    return ModelLibrary(tmp_path / "lib", descriptor_config=FAST_DESCRIPTORS)


def test_add_get_roundtrip_keeps_points_colors_and_metadata(lib, tmp_path):
    pcd = box_surface()
    meta = ModelMetadata(object_name="red box", session="/s/1", configuration="no_region",
                         quality={"chamfer_mm": 1.5}, extra={"operator": "me"})
    entry_id = lib.add(pcd, meta)
    assert entry_id.startswith("red-box-")
    entry = lib.get(entry_id)
    assert entry.metadata.object_name == "red box"
    assert entry.metadata.quality == {"chamfer_mm": 1.5}
    assert entry.metadata.extra["operator"] == "me"
    assert entry.points == 3000
    back = o3d.io.read_point_cloud(str(entry.model_path))
    np.testing.assert_allclose(np.asarray(back.points), np.asarray(pcd.points), atol=1e-9)
    np.testing.assert_allclose(np.asarray(back.colors), np.asarray(pcd.colors), atol=1 / 255)
    on_disk = json.loads((entry.path / "metadata.json").read_text())
    assert on_disk["id"] == entry_id and on_disk["metadata"]["object_name"] == "red box"


def test_whole_model_descriptor_is_stored_and_rotation_invariant(lib):
    pcd = box_surface()
    a = lib.get(lib.add(pcd, {"object_name": "box"})).metadata.descriptor
    R = o3d.geometry.get_rotation_matrix_from_xyz((0.3, -0.7, 1.9))
    rotated = o3d.geometry.PointCloud(pcd).rotate(R, center=(0.1, 0.2, 0.3)).translate((1.0, -2.0, 0.5))
    b = lib.get(lib.add(rotated, {"object_name": "box"})).metadata.descriptor
    assert a["kind"] == "GOOD" and a["n_bins"] == [5, 10]
    whole = np.asarray(a["whole"])
    assert whole.shape == (3 * 25 + 3 * 100,)
    np.testing.assert_allclose(whole, describe(np.asarray(pcd.points), FAST_DESCRIPTORS), atol=1e-7)
    for start, size in ((0, 25), (25, 25), (50, 25), (75, 100), (175, 100), (275, 100)):
        assert whole[start:start + size].sum() == pytest.approx(1.0)
    # the same object turned and moved gets (nearly) the same descriptor; a different shape does not
    c = lib.get(lib.add(box_surface(size=(0.12, 0.12, 0.03)), {"object_name": "flat"})).metadata.descriptor
    same = np.abs(whole - np.asarray(b["whole"])).sum()
    other = np.abs(whole - np.asarray(c["whole"])).sum()
    assert same < 0.25 * other


def test_list_orders_by_date_and_filters_by_object(lib):
    ids = [lib.add(box_surface(seed=i), ModelMetadata(object_name=name, created=1000.0 + i))
           for i, name in enumerate(["b", "a", "b"])]
    assert [e.id for e in lib.list()] == ids
    assert [e.id for e in lib.list("b")] == [ids[0], ids[2]]
    assert len(lib) == 3


def test_unique_prefix_finds_entry_and_ambiguous_or_unknown_ids_are_typed_errors(lib):
    a = lib.add(box_surface(), ModelMetadata(object_name="mug", created=0.0))
    b = lib.add(box_surface(), ModelMetadata(object_name="mug", created=0.0))
    assert lib.get(a[:-1]).id == a  # a unique prefix (the random suffixes differ in 5 of 6 digits)
    assert lib.get(a).id == a and lib.get(b).id == b
    with pytest.raises(ModelNotFound) as exc:
        lib.get("mug-")
    assert exc.value.code == "ambiguous_id" and sorted(exc.value.detail["matches"]) == sorted([a, b])
    with pytest.raises(ModelNotFound) as exc:
        lib.get("nothing")
    assert exc.value.code == "model_not_found"
    with pytest.raises(ModelNotFound):
        lib.get("mug_%")  # LIKE wildcards are literal


def test_export_to_folder_and_to_ply(lib, tmp_path):
    mesh = o3d.geometry.TriangleMesh.create_box(0.05, 0.05, 0.1)
    entry_id = lib.add(box_surface(), {"object_name": "box"}, mesh=mesh)
    files = lib.export(entry_id, tmp_path / "out")
    assert sorted(p.name for p in files) == ["mesh.ply", "metadata.json", "model.ply"]
    assert len(o3d.io.read_point_cloud(str(tmp_path / "out" / "model.ply")).points) == 3000
    assert len(o3d.io.read_triangle_mesh(str(tmp_path / "out" / "mesh.ply")).triangles) == 12
    files = lib.export(entry_id, tmp_path / "single" / "box.ply")
    assert (tmp_path / "single" / "box.ply").is_file() and (tmp_path / "single" / "box.json").is_file()
    assert not list((tmp_path / "single").glob(".*tmp"))
    assert len(files) == 3


def test_delete_removes_files_and_row(lib):
    keep = lib.add(box_surface(), {"object_name": "keep"})
    gone = lib.add(box_surface(), {"object_name": "gone"})
    path = lib.get(gone).path
    assert lib.delete(gone[:8]) == gone
    assert not path.exists()
    assert [e.id for e in lib.list()] == [keep]
    with pytest.raises(ModelNotFound):
        lib.delete(gone)


@pytest.mark.parametrize("bad, code", [
    (np.zeros((0, 3)), "empty_cloud"),
    (np.full((100, 3), np.nan), "bad_model"),
    (np.zeros((100, 2)), "bad_model"),
    ("does/not/exist.ply", "io_error"),
    (42, "bad_model"),
])
def test_bad_models_are_typed_errors_and_store_nothing(lib, bad, code):
    with pytest.raises(BadModelInput) as exc:
        lib.add(bad, {"object_name": "x"})
    assert exc.value.code == code
    assert len(lib) == 0
    assert not any((lib.root / ENTRIES).iterdir()) and not any((lib.root / STAGING).iterdir())


@pytest.mark.parametrize("meta", [{}, {"object_name": ""}, {"object_name": "x", "quality": [1]}, "milk"])
def test_bad_metadata_is_rejected(lib, meta):
    with pytest.raises(BadModelInput):
        lib.add(box_surface(), meta)
    assert len(lib) == 0


def test_unknown_metadata_keys_are_kept_in_extra(lib):
    entry_id = lib.add(box_surface(), {"object": "milk", "lot": 7})
    meta = lib.get(entry_id).metadata
    assert meta.object_name == "milk" and meta.extra["lot"] == 7


def test_concurrent_adds_from_two_threads_are_both_indexed(tmp_path):
    root = tmp_path / "lib"
    ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
    ids: list[str] = []

    def worker(i: int) -> None:
        lib = ModelLibrary(root, descriptor_config=FAST_DESCRIPTORS)
        for j in range(2):
            ids.append(lib.add(box_surface(seed=10 * i + j), {"object_name": f"t{i}"}))

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    lib = ModelLibrary(root)
    assert sorted(e.id for e in lib.list()) == sorted(ids) and len(ids) == 4
    assert not lib.last_reconcile.changed()


def test_newer_index_schema_is_refused(tmp_path):
    import sqlite3

    lib = ModelLibrary(tmp_path / "lib")
    db = sqlite3.connect(lib.root / "index.sqlite")
    db.execute("PRAGMA user_version = 99")
    db.commit()
    db.close()
    with pytest.raises(Exception) as exc:
        ModelLibrary(tmp_path / "lib")
    assert getattr(exc.value, "code", None) == "library_version"

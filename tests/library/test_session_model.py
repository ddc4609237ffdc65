"""``add_session_model``: the model of a finished acquisition goes into the library with its facts."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from services.library import BadModelInput, ModelLibrary, add_session_model
from tests.conftest import shared_data
from tests.library.fake_session import build_fake_session


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    shared_data("hope", "milk")
    return build_fake_session(tmp_path_factory.mktemp("sess") / "milk_session", "milk", views=4, turn_deg=90.0)


def test_session_model_is_stored_with_its_facts(session, tmp_path):
    root = tmp_path / "models"
    entry_id = add_session_model(root, session)
    entry = ModelLibrary(root).get(entry_id)
    report = json.loads((session / "report.json").read_text())
    meta = entry.metadata
    assert meta.object_name == "milk" and meta.source == "session"
    assert meta.session == str(session.resolve())
    assert meta.configuration == report["model_figures"]["configuration"] == "no_region"
    assert meta.quality["chamfer_mm"] == pytest.approx(report["accuracy"]["chamfer_mm"])
    assert meta.quality["points"] == report["points"]
    fits = [e["fitness"] for e in report["model_figures"]["edges"]]
    assert meta.quality["edge_fitness_min"] == pytest.approx(min(fits))
    assert meta.extra["profile"] == "ideal" and meta.extra["views"] == 4
    assert len(meta.descriptor["whole"]) == 375
    stored = np.asarray(o3d.io.read_point_cloud(str(entry.model_path)).points)
    original = np.asarray(o3d.io.read_point_cloud(str(session / "model.ply")).points)
    np.testing.assert_allclose(stored, original)


def test_adding_the_same_session_twice_returns_the_first_entry(session, tmp_path):
    root = tmp_path / "models"
    first = add_session_model(root, session)
    assert add_session_model(root, session) == first
    assert len(ModelLibrary(root)) == 1


def test_session_without_model_is_a_typed_error(tmp_path):
    (tmp_path / "s").mkdir()
    with pytest.raises(BadModelInput) as exc:
        add_session_model(tmp_path / "lib", tmp_path / "s")
    assert exc.value.code == "no_model"

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


def _copy_with_verdict(session, tmp_path, accepted: bool, where: str):
    """A copy of the session whose report carries the dynamic stage's verdict (top level or in the figures)."""
    import shutil

    dest = tmp_path / f"session_{accepted}_{where}"
    shutil.copytree(session, dest)
    report = json.loads((dest / "report.json").read_text())
    verdict = {"accepted": accepted, "why": "" if accepted else "loop closure 89.80 deg > 5 deg"}
    if where == "top":
        report.update(verdict)
    else:
        report["model_figures"].update(verdict)
    (dest / "report.json").write_text(json.dumps(report))
    return dest


@pytest.mark.parametrize("where", ["top", "figures"])
def test_an_unaccepted_model_is_refused_unless_allowed(session, tmp_path, where):
    from services.library import UnacceptedModel

    bad = _copy_with_verdict(session, tmp_path, False, where)
    root = tmp_path / "models"
    with pytest.raises(UnacceptedModel) as exc:
        add_session_model(root, bad)
    assert exc.value.code == "model_not_accepted" and "loop closure" in exc.value.message
    assert len(ModelLibrary(root)) == 0  # nothing stored
    entry = ModelLibrary(root).get(add_session_model(root, bad, allow_unaccepted=True))
    assert entry.metadata.quality["accepted"] is False and "loop closure" in entry.metadata.quality["why"]


def test_an_accepted_model_is_stored_with_its_verdict(session, tmp_path):
    good = _copy_with_verdict(session, tmp_path, True, "top")
    entry = ModelLibrary(tmp_path / "models").get(add_session_model(tmp_path / "models", good))
    assert entry.metadata.quality["accepted"] is True

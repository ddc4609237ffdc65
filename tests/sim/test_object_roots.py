"""The twin loads objects only from its configured roots, and says the same about "not allowed" and "not there".

A ``sim/world`` reset used to resolve any path on the machine, and its answers told what exists
(``/etc`` -> "no mesh in folder /etc", ``/nonexistent`` -> "unknown object"). The service process is
asked over Zenoh as a requester on the network would ask it.
"""

from __future__ import annotations

import os

import pytest

from common import keys
from common.client import request_sync
from common.errors import RemoteError
from common.launcher import ProcessSpec
from common.messages import Request
from services.sim.object_roots import ObjectRoots, start_args
from tests.sim.meshes import write_box_ply

pytestmark = pytest.mark.timeout(240)
ROBOT = keys.DEFAULT_ROBOT


def _reset(group, obj: str | None = None):  # noqa: ANN001, ANN202
    params = {"op": "reset"} if obj is None else {"op": "reset", "object": obj}
    return request_sync(group.session, keys.sim(ROBOT, "world"), Request(params=params), timeout=60.0)


def _refusal(group, obj: str) -> tuple[str, str, dict]:  # noqa: ANN001
    """(code, message, detail) of the refused reset, with the requested name taken out."""
    with pytest.raises(RemoteError) as exc:
        _reset(group, obj)
    e = exc.value
    detail = {k: v for k, v in e.detail.items() if k not in ("name", "key")}
    return e.code, e.message.replace(repr(obj), "<name>"), detail


def test_the_twin_answers_the_same_for_etc_and_a_missing_path(service_group, tmp_path):
    start = write_box_ply(tmp_path / "start", (0.06, 0.06, 0.15), name="carton")
    allowed_dir = tmp_path / "objects"
    allowed = write_box_ply(allowed_dir, (0.05, 0.07, 0.12), name="tea")
    outside = write_box_ply(tmp_path / "elsewhere", (0.05, 0.05, 0.10), name="secret")  # a real mesh, not allowed
    (tmp_path / "no_mesh").mkdir()
    os.symlink(outside, allowed_dir / "link.ply")  # inside a root by name, outside by where it points
    service_group.launch([ProcessSpec("services.sim", ["--object", str(start), "--object-dir", str(allowed_dir),
                                                       "--state-file", "none"], service="sim")], timeout=120)

    answers = {name: _refusal(service_group, name) for name in (
        "/etc", "/nonexistent", "/etc/passwd", "/root", "etc", "../../../../etc",
        str(tmp_path / "no_mesh"), str(outside), str(tmp_path / "elsewhere"), str(allowed_dir / "link.ply"),
        str(allowed_dir / "absent.ply"), str(start.parent / "absent.ply"), "no_such_hope_object", "")}
    assert answers["/etc"][0] == "object_not_found"
    assert answers["/etc"] == answers["/nonexistent"], (answers["/etc"], answers["/nonexistent"])
    different = {name: a for name, a in answers.items() if a != answers["/nonexistent"]}
    assert not different, different
    assert "/etc" not in answers["/etc"][1] and "folder" in answers["/etc"][1]  # names the roots, not the path

    # what it may load: the start mesh, a mesh in an object folder, the current object (no name given)
    assert _reset(service_group, str(allowed)).info["object"] == "tea"
    assert _reset(service_group).info["object"] == "tea"
    assert _reset(service_group, str(start)).info["object"] == "carton"
    assert _reset(service_group, "carton").info["object"] == "carton"  # the world's own object, by its name
    # the twin keeps serving after the refusals
    state = request_sync(service_group.session, keys.sim(ROBOT, "world"), Request(params={"op": "state"}))
    assert state.info["object"] == "carton"
    # the demo objects need no configuration: by name, whatever the twin was started with
    assert _reset(service_group, "flat_box").info["object"] == "flat_box"


def test_roots_are_the_hope_folder_the_object_folders_and_the_start_mesh(tmp_path, monkeypatch):
    """Unit face of the same gate: environment folders count, and the answer never depends on existence."""
    monkeypatch.setenv("OBJSCAN_HOPE_DIR", str(tmp_path / "hope"))
    (tmp_path / "hope").mkdir()
    env_dir = tmp_path / "env_objects"
    mesh = write_box_ply(env_dir, (0.05, 0.05, 0.1), name="jar")
    roots = ObjectRoots.configured(None, (), env={"OBJSCAN_SIM_OBJECT_DIRS": str(env_dir)})
    assert roots.check(str(mesh)) == str(mesh)
    errors = []
    for name in ("/etc", "/nonexistent", str(tmp_path)):
        with pytest.raises(Exception) as exc:
            roots.check(name)
        errors.append((exc.value.code, exc.value.message.replace(repr(name), "<name>")))
    assert len(set(errors)) == 1 and errors[0][0] == "object_not_found"
    # a command that starts its own twin for a user's mesh names it at start; a HOPE name needs nothing
    assert start_args("milk") == [] and start_args(str(mesh)) == ["--object", str(mesh.resolve())]

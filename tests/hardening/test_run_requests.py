"""Through the real orchestrator process: a ``run`` request with a bad config or a path
outside the configured roots gets a typed error, nothing is created, and the service keeps answering.

Why: ``views: 3.5`` or NaN were accepted (the session stayed ``running`` forever), ``views: 100000000``
blocked the event loop, and ``out``/``resume``/``library`` were taken as given (the folder was created
before anything was checked; ``library`` let a request tidy any folder)."""

from __future__ import annotations

import math
import time

import pytest

from common import keys
from common.client import request_sync
from common.errors import RemoteError
from common.launcher import ProcessSpec
from common.messages import Ok, Request

ROBOT = keys.DEFAULT_ROBOT


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("roots")


@pytest.fixture(scope="module")
def orchestrator(root):
    from common.launcher import ServiceGroup

    (root / "sessions").mkdir()
    with ServiceGroup(log_dir=root / "logs") as group:
        group.launch([ProcessSpec("services.orchestrator", ["--sessions", str(root / "sessions"),
                                                            "--library", str(root / "lib")],
                                  service="orchestrator")], timeout=120)
        yield group


@pytest.fixture
def tmp_path(root, request):
    """This module's tests share one orchestrator, so their folders live under its roots."""
    return root


def _run(group, params):
    return request_sync(group.session, keys.orchestrator(ROBOT, "run"), Request(params=params), timeout=20)


@pytest.mark.parametrize(("config", "field"), [({"views": 3.5}, "views"), ({"views": math.nan}, "views"),
                                               ({"views": 100_000_000}, "views"), ({"turn_deg": -30}, "turn_deg"),
                                               ({"width": "640"}, "width"), ({"viewz": 12}, "config"),
                                               ({"turn": {"speed_scale": math.inf}}, "turn.speed_scale")])
def test_bad_configs_are_refused_and_the_service_answers(orchestrator, tmp_path, config, field):
    t0 = time.perf_counter()
    with pytest.raises(RemoteError) as err:
        _run(orchestrator, {"out": "s1", "config": config})
    assert err.value.code == "invalid_config" and err.value.detail["field"] == field
    assert time.perf_counter() - t0 < 10
    assert not (tmp_path / "sessions" / "s1").exists()
    status = request_sync(orchestrator.session, keys.orchestrator(ROBOT, "status"), timeout=10)
    assert isinstance(status, Ok) and status.info["status"] == "idle"


def test_paths_outside_the_roots_are_refused_before_anything_is_created(orchestrator, tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "entries").mkdir()
    (victim / "entries" / "keep.txt").write_text("mine")
    cases = [{"out": str(tmp_path / "elsewhere")}, {"out": "../escape"}, {"out": str(tmp_path / "sessions")},
             {"resume": str(victim)}, {"out": "ok", "library": str(victim)},
             {"out": "ok2", "library": str(tmp_path / "lib" / ".." / "victim")}]
    (tmp_path / "sessions" / "link").symlink_to(victim, target_is_directory=True)
    cases.append({"out": "link/inside"})
    for params in cases:
        with pytest.raises(RemoteError) as err:
            _run(orchestrator, params)
        assert err.value.code == "path_not_allowed", params
    assert not (tmp_path / "elsewhere").exists() and not (tmp_path / "escape").exists()
    assert sorted(p.name for p in victim.rglob("*")) == ["entries", "keep.txt"]
    assert "ok" not in {p.name for p in (tmp_path / "sessions").iterdir()}


def test_a_non_session_folder_is_neither_adopted_nor_resumed(orchestrator, tmp_path):
    foreign = tmp_path / "sessions" / "photos"
    assert not foreign.exists()
    foreign.mkdir()
    (foreign / "cat.jpg").write_bytes(b"\xff\xd8")
    for params, code in (({"out": "photos"}, "not_a_session"), ({"resume": "photos"}, "not_a_session")):
        with pytest.raises(RemoteError) as err:
            _run(orchestrator, params)
        assert err.value.code == code
    assert sorted(p.name for p in foreign.iterdir()) == ["cat.jpg"]

"""A service that dies while starting: its starter reports the service's own typed error, not an exit code."""

from __future__ import annotations

import pytest

from common.errors import ObjscanError, ServiceStartError
from common.fatal import read_fatal, start_error, write_fatal
from common.launcher import ProcessSpec


def test_launch_raises_the_dying_services_own_code_and_message(service_group):
    with pytest.raises(ServiceStartError) as exc:
        service_group.launch([ProcessSpec("tests.support.failing_service", ["--code", "object_not_found"],
                                          service="failing")], timeout=120)
    err = exc.value
    assert err.code == "object_not_found", err
    assert err.message == "failing could not start: cannot start: the object_not_found it was given"
    assert err.detail["given"] == "object_not_found" and err.detail["service"] == "failing"
    assert err.detail["exit_code"] == 1 and err.detail["log"].endswith("failing.log")


def test_an_untyped_start_failure_is_internal_with_its_exception(service_group):
    with pytest.raises(ServiceStartError) as exc:
        service_group.launch([ProcessSpec("tests.support.failing_service", ["--code", "plain"], service="failing")],
                             timeout=120)
    assert exc.value.code == "internal"
    assert "RuntimeError: a plain exception while starting" in exc.value.message


def test_fatal_file_round_trip_and_a_silent_death(tmp_path):
    path = tmp_path / "sim.json"
    write_fatal("sim", ObjscanError("unknown object 'x'", code="object_not_found", detail={"known": ["a"]}), path)
    doc = read_fatal(path)
    assert doc == {"service": "sim", "code": "object_not_found", "message": "unknown object 'x'",
                   "detail": {"known": ["a"]}}
    assert read_fatal(tmp_path / "absent.json") is None
    (tmp_path / "junk.json").write_text("not json")
    assert read_fatal(tmp_path / "junk.json") is None
    silent = start_error("arm", -9, None, tmp_path / "arm.log")  # killed: nothing written, the log is named
    assert silent.code == "service_exited" and "arm exited with code -9 before it was live" in silent.message
    assert str(tmp_path / "arm.log") in silent.message

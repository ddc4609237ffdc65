"""A whole acquisition behind the shipped TLS + access-control router, every service with its own identity.

The access rules are tight (each identity may only serve its own keys and ask whom it must); this shows
they are not too tight: the operator starts a 3-view scan through the orchestrator, and the orchestrator,
camera, arm, sim, grasp and registration finish it over mutual TLS, with the model written. Slow: one
whole acquisition.
"""

from __future__ import annotations

import json
import shutil
import time

import pytest

from common import keys
from common.client import request_sync
from common.errors import ObjscanError
from common.messages import Ok, Request
from tests.security.tls_cell import TlsCell

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is needed to make certificates")

ROBOT = keys.DEFAULT_ROBOT
CONFIG = {"object": "milk", "views": 3, "profile": "robot-turned", "seed": 0, "width": 640, "height": 480}


def _status(cell: TlsCell) -> dict:
    try:
        reply = request_sync(cell.group.session, keys.orchestrator(ROBOT, "status"), timeout=10)
    except ObjscanError:
        return {}
    return dict(reply.info) if isinstance(reply, Ok) else {}


@pytest.mark.slow
@pytest.mark.timeout(2400)
def test_a_whole_acquisition_runs_under_mutual_tls_and_access_control(tmp_path):
    cell = TlsCell(tmp_path)
    session = tmp_path / "session"
    try:
        cell.start_router()
        cell.launch(["sim", "camera", "arm", "registration", "grasp", "orchestrator"], timeout=240)
        reply = request_sync(cell.group.session, keys.orchestrator(ROBOT, "run"),
                             Request(params={"out": str(session), "config": CONFIG}), timeout=30)
        assert isinstance(reply, Ok), reply
        deadline = time.monotonic() + 2000
        status: dict = {}
        while time.monotonic() < deadline and status.get("status") not in ("done", "failed", "stopped"):
            time.sleep(2.0)
            status = _status(cell) or status
    finally:
        cell.close()
    journal = json.loads((session / "journal.json").read_text())
    assert journal["status"] == "done", (journal.get("error"), f"logs in {tmp_path / 'logs'}")
    assert (session / "model.ply").is_file()
    assert sorted(p.name for p in session.glob("view_??")) == ["view_00", "view_01", "view_02"]
    report = json.loads((session / "report.json").read_text())
    assert report, "the model's report exists"

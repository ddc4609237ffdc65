"""The orchestrator process is SIGKILLed mid-session: its recording stays readable, and the resumed run
records into a new part without touching the first."""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np
import pytest

from common import keys
from common.client import request_sync
from common.errors import ObjscanError
from common.launcher import ServiceGroup
from common.messages import Ok, Request
from common.session_folder import read_scan, read_session
from services.cell import cell_specs
from services.recording.reader import read_recording
from services.recording.recorder import recording_parts
from tests.recording.test_session_replay import _assert_same_model, _wait_closed, _wait_status

ROBOT = keys.DEFAULT_ROBOT
CONFIG = {"object": "milk", "views": 3, "profile": "robot-turned", "seed": 5, "width": 640, "height": 480}


def _status(group: ServiceGroup) -> dict:
    try:
        reply = request_sync(group.session, keys.orchestrator(ROBOT, "status"), timeout=5)
    except ObjscanError:
        return {}
    return dict(reply.info) if isinstance(reply, Ok) else {}


@pytest.mark.slow
@pytest.mark.timeout(2400)  # two partial acquisitions on a 2-core machine: well over the default 600 s
def test_killed_orchestrator_recording_is_readable_and_resume_appends_a_part(tmp_path):
    session = tmp_path / "session"
    with ServiceGroup(log_dir=tmp_path / "logs", robot=ROBOT) as group:
        group.launch(cell_specs(extra_args={"orchestrator": ["--sessions", str(tmp_path)]}), timeout=240)
        request_sync(group.session, keys.orchestrator(ROBOT, "run"),
                     Request(params={"out": str(session), "config": CONFIG}), timeout=30)
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:  # kill it while it works on view 1
            s = _status(group)
            if s.get("view") == 1 and s.get("state") == "scan":
                break
            assert s.get("status") not in ("done", "failed"), s
            time.sleep(0.3)
        time.sleep(1.0)
        group.kill("orchestrator")

        first = session / "session.mcap"
        rec = read_recording(first)
        assert rec.truncated == [first]  # killed: no footer, read anyway
        frames = [e.reply_message() for e in rec.exchanges_on(keys.camera_capture(ROBOT))]
        info = read_session(session)
        saved = [(v, j) for v in (0, 1) for j in (info.scans(v) if (session / f"view_{v:02d}").is_dir() else [])]
        assert saved, "nothing was captured before the kill"
        for v, j in saved:  # every frame the folder holds is in the recording, byte for byte
            f = read_scan(session, v, j)
            assert any(np.array_equal(f.depth, r.depth) and np.array_equal(f.color, r.color) for r in frames), (v, j)
        digest = hashlib.sha256(first.read_bytes()).hexdigest()

        spec = next(s for s in cell_specs(["orchestrator"], extra_args={"orchestrator": ["--sessions", str(tmp_path)]}))
        group.start(spec)
        group.wait_alive(["orchestrator"], timeout=120)
        request_sync(group.session, keys.orchestrator(ROBOT, "run"), Request(params={"resume": str(session)}),
                     timeout=30)
        try:
            status = _wait_status(group, 1500)
        except TimeoutError as exc:  # say where it stood: the resumed orchestrator's last words
            log = (tmp_path / "logs" / "orchestrator.log").read_text(errors="replace").splitlines()[-40:]
            raise AssertionError(f"{exc}\n" + "\n".join(log)) from exc
        assert status["status"] == "done", status
        _wait_closed(session / "session.part1.mcap")

    assert hashlib.sha256(first.read_bytes()).hexdigest() == digest  # the first part was never touched
    assert recording_parts(session) == [first, session / "session.part1.mcap"]
    both = read_recording(session)
    assert both.metadata["session.part1"]["resumed"] is True
    assert len(both.exchanges_on(keys.REGISTRATION_DYNAMIC)) == 1

    from services.recording.registration import replay_registration

    report = replay_registration(session, tmp_path / "replay")  # registration from the two parts
    _assert_same_model(report["comparison"])
    assert json.loads((tmp_path / "replay" / "replay.json").read_text())["views"] == [0, 1, 2]

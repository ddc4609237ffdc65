"""The typed journal (services/orchestrator/journal.py) reads journals the old dict code wrote, and a
session written by the old code still resumes."""

from __future__ import annotations

import asyncio
import json

import pytest

from common.session_folder import atomic_write_json
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.journal import JOURNAL_VERSION, Journal
from services.orchestrator.machine import Acquisition
from services.session_store import SessionStore
from tests.orchestrator.test_run_ends import RefusingCell


def _old_journal(**over) -> dict:
    """A journal exactly as the dict-based machine.py (sessions 1-4) wrote it mid-run: keys added with
    ``setdefault`` as the run went, counters without the later ones, an ``updated`` stamp."""
    j = {"version": 1, "config": AcquisitionConfig(views=3).to_dict(), "state": "plan_grasp", "view": 1,
         "status": "running", "turns_deg": [0.0, 30.0], "centers": {"-1": [0.6, 0.0, 0.0], "0": [0.6, 0.01, 0.0]},
         "heights": {"-1": 0.2, "0": 0.19}, "rescans": {"0": 1}, "grasp_mode": "auto",
         "scan_sets": {"1": [[[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]] * 3},
         "decisions": [{"t": 0.1, "state": "locate", "view": 0, "what": "cell ready", "simulated": True}],
         "timings_s": {"locate": 1.5}, "counters": {"captures": 7, "grasp_attempts": 1, "slips": 0, "rescans": 1},
         "started": 1700000000.0, "simulated": True, "error": None, "turn_direction": 1,
         "failed_grasps": {"0": ["frontal:0:grasp"]}, "limits": {"0": {"planner": {"too_wide": 3}}},
         "turn_intent": None, "holding": False, "updated": 1700000100.0, "a_key_from_elsewhere": {"x": 1}}
    j.update(over)
    return j


def test_an_old_journal_loads_field_by_field():
    j = Journal.from_dict(_old_journal())
    assert (j.state, j.view, j.turns_deg, j.turn_direction) == ("plan_grasp", 1, [0.0, 30.0], 1)
    assert j.counters.captures == 7 and j.counters.grasp_attempts == 1 and j.counters.grasp_checks == 0
    assert j.failed_grasps == {"0": ["frontal:0:grasp"]} and j.limits_of(0)["planner"] == {"too_wide": 3}
    assert j.previous_errors == [] and j.pending_rescan is None and j.topple_restarts == 0
    out = j.to_dict()
    assert out["version"] == JOURNAL_VERSION and out["a_key_from_elsewhere"] == {"x": 1}  # kept, not dropped
    assert out["counters"]["captures"] == 7 and "updated" not in out  # the store stamps it on every write
    written = json.loads(json.dumps(out))
    assert json.loads(json.dumps(Journal.from_dict(written).to_dict())) == written  # the new form round-trips


def test_a_journal_without_the_keys_added_later_loads_with_defaults():
    old = _old_journal()
    for key in ("turn_direction", "failed_grasps", "limits", "turn_intent", "holding"):
        old.pop(key)
    j = Journal.from_dict(old)
    assert j.turn_direction is None and j.failed_grasps == {} and j.limits == {} and j.holding is False


def test_updating_an_unknown_field_is_an_error():
    j = Journal(config={})
    with pytest.raises(AttributeError, match="turn_directon"):
        j.update(turn_directon=1)


def test_a_failed_session_written_by_the_old_code_resumes(tmp_path):
    atomic_write_json(tmp_path / "journal.json", _old_journal(
        state="failed", status="failed", rescans={"1": 2},
        error={"code": "acquisition_failed", "message": "view 1: giving up", "state": "register"}))
    cell = RefusingCell(RuntimeError("arm unplugged"))
    acq = Acquisition(cell, SessionStore(tmp_path), AcquisitionConfig())  # type: ignore[arg-type]
    assert acq.resumed and acq.config.views == 3  # the journal's config, not the one passed
    asyncio.run(asyncio.wait_for(acq.run(), 30))
    journal = json.loads((tmp_path / "journal.json").read_text())
    retry = [d for d in journal["decisions"] if d["what"] == "resumed after failure"]
    assert retry and retry[0]["state"] == "register"
    assert "gripper" in cell.asked  # it ran again from where it failed
    assert journal["previous_errors"][0]["code"] == "acquisition_failed"
    assert journal["counters"]["captures"] == 7 and journal["turns_deg"] == [0.0, 30.0]
    assert journal["decisions"][0]["what"] == "cell ready"  # the old decisions are kept

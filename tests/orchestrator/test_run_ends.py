"""Whatever goes wrong, ``Acquisition.run`` ends with a status a user can read: a failure at the very start
(the cell's first command refused, or a bug) marks the session ``failed`` with the reason, parks the arm and
persists the journal; it never leaves the session ``running`` forever (a CI run once hung this way: a resumed
orchestrator's first gripper command was refused with 'another motion is running' outside the guarded loop)."""

from __future__ import annotations

import asyncio
import json

import pytest

from common.errors import RemoteError
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition
from services.session_store import SessionStore


class RefusingCell:
    """A cell whose twin is absent and whose every arm command raises ``error``; it records what was asked."""

    def __init__(self, error: Exception):
        self.error = error
        self.asked: list[str] = []

    async def sim(self, op: str, **kw):  # noqa: ANN003, ANN201
        self.asked.append(f"sim/{op}")
        raise RemoteError("no twin", code="unavailable")

    async def gripper(self, opening: float, force: float = 30.0):  # noqa: ANN201
        self.asked.append("gripper")
        raise self.error

    async def clear_object_box(self) -> None:
        self.asked.append("scene")
        raise self.error

    async def move(self, kind: str, **kw):  # noqa: ANN003, ANN201
        self.asked.append(f"move/{kind}")
        raise self.error


@pytest.mark.parametrize(("error", "code"), [(RemoteError("another motion is running", code="busy"), "busy"),
                                             (ZeroDivisionError("a bug"), "internal")])
def test_a_failure_before_the_first_state_ends_the_session_failed(tmp_path, error, code):
    cell = RefusingCell(error)
    acq = Acquisition(cell, SessionStore(tmp_path), AcquisitionConfig(views=3))  # type: ignore[arg-type]
    status = asyncio.run(asyncio.wait_for(acq.run(), 30))
    assert status["status"] == "failed" and status["last_error"]["code"] == code
    assert "move/home" in cell.asked  # parked (each park step tried even though each failed)
    journal = json.loads((tmp_path / "journal.json").read_text())
    assert journal["status"] == "failed" and journal["error"]["code"] == code


class StatingTwinCell(RefusingCell):
    """A twin that states its pose and turn accuracy at reset, then refuses the first gripper command."""

    async def sim(self, op: str, **kw):  # noqa: ANN003, ANN201
        self.asked.append(f"sim/{op}")
        return {"pose_accuracy": {"position_sigma_mm": 3.0, "orientation_sigma_deg": 1.0}, "turn_accuracy_deg": 4.2}


def test_a_session_whose_twin_stated_its_turn_accuracy_can_be_resumed(tmp_path):
    cell = StatingTwinCell(RemoteError("another motion is running", code="busy"))
    acq = Acquisition(cell, SessionStore(tmp_path), AcquisitionConfig(views=3))  # type: ignore[arg-type]
    assert asyncio.run(asyncio.wait_for(acq.run(), 30))["status"] == "failed"
    journal = json.loads((tmp_path / "journal.json").read_text())
    resumed = AcquisitionConfig.from_dict(journal["config"])  # what a resuming orchestrator does
    assert resumed.turn_accuracy_deg == 4.2
    assert resumed.pose_accuracy == {"position_sigma_mm": 3.0, "orientation_sigma_deg": 1.0}

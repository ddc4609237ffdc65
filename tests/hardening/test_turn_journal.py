"""A journal written before every irreversible step, and a resume that knows what the
arm holds.

Why: a resume's first command opened the gripper, dropping a held
object; a kill during a
re-scan (old view folder moved aside, journal not yet saved) made the resume fail, and a kill right after a
turn finished physically, before it was journalled, made the resume turn the object again."""

from __future__ import annotations

import asyncio
import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest

from common.errors import RemoteError
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition, State
from services.session_store import SessionStore


class ScriptedArmCell:
    """An arm that reports a given gripper pose and opening and records every command; no twin; the camera
    refuses (so a run ends at its first capture)."""

    def __init__(self, T: np.ndarray, opening: float):
        self.T, self.opening = np.asarray(T, float), opening
        self.asked: list[tuple] = []

    async def sim(self, op, **kw):  # noqa: ANN001, ANN003, ANN201
        raise RemoteError("no twin", code="unavailable")

    async def state(self):  # noqa: ANN201
        self.asked.append(("state",))
        return SimpleNamespace(T_base_gripper=self.T.copy(), gripper_opening=self.opening, position=np.zeros(6))

    async def gripper(self, opening, force=30.0):  # noqa: ANN001, ANN201
        self.asked.append(("gripper", round(float(opening), 3)))
        self.opening = opening
        return SimpleNamespace(opening=opening, holding=False, reason="")

    async def move(self, kind, *, target=None, **kw):  # noqa: ANN001, ANN003, ANN201
        self.asked.append(("move", kind, None if target is None else round(float(np.asarray(target)[2, 3]), 3)))
        if target is not None and kind != "home":
            self.T = np.asarray(target, float)
        return SimpleNamespace(q=np.zeros(6), T_base_gripper=self.T, T_base_camera=self.T)

    async def set_object_box(self, c, e):  # noqa: ANN001, ANN201
        self.asked.append(("scene",))

    async def clear_object_box(self):  # noqa: ANN201
        self.asked.append(("scene",))

    async def plan_grasps(self, *a):  # noqa: ANN002, ANN201
        self.asked.append(("plan",))
        raise RemoteError("no planner here", code="no_planner")

    async def capture(self, w, h):  # noqa: ANN001, ANN201
        self.asked.append(("capture",))
        raise RemoteError("no camera here", code="camera_error")


def _pose(z: float, yaw_deg: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = [0.6, 0.0, z]
    return T


def _session_in_turn(path, phase: str, release_T: np.ndarray) -> SessionStore:
    """A journal as a killed orchestrator leaves it mid-turn of view 0 (the intent written, nothing after)."""
    store = SessionStore(path)
    acq = Acquisition(ScriptedArmCell(np.eye(4), 0.1), store, AcquisitionConfig(views=3))  # type: ignore[arg-type]
    acq.j.update(state="turn", view=0, simulated=False, scan_sets={"0": [np.eye(4).tolist()] * 3},
                 turn_intent={"phase": phase, "view": 0, "direction": 1, "opening": 0.09,
                              "release_T": release_T.tolist(), "center": [0.6, 0.0, 0.0], "height": 0.2},
                 holding=phase == "holding")
    store.save_journal(acq.j.to_dict())
    return store


def _resume(store, cell) -> dict:
    acq = Acquisition(cell, store, AcquisitionConfig())  # type: ignore[arg-type]
    asyncio.run(asyncio.wait_for(acq.run(), 60))
    return json.loads((store.path / "journal.json").read_text())


def test_resume_while_holding_sets_the_object_down_before_opening(tmp_path):
    release = _pose(0.15, 30.0)
    store = _session_in_turn(tmp_path, "holding", release)
    cell = ScriptedArmCell(_pose(0.17, 12.0), opening=0.04)  # cut off mid-turn, the fingers closed on it
    journal = _resume(store, cell)
    first_open = next(i for i, a in enumerate(cell.asked) if a[0] == "gripper" and a[1] > 0.04)
    lowered = [i for i, a in enumerate(cell.asked[:first_open]) if a[0] == "move" and a[2] is not None and a[2] < 0.17]
    assert lowered, cell.asked  # the hand went down with the object before the fingers opened
    assert journal["turns_deg"] == [0.0]  # it did not count as a turn
    assert journal["rescans"] == {"0": 1} and (tmp_path / "view_00_attempt1").exists() is False  # nothing to move
    assert any(d["what"] == "re-scan" for d in journal["decisions"])


def test_a_turn_that_finished_before_the_kill_is_recorded_not_repeated(tmp_path):
    release = _pose(0.15, 30.0)
    store = _session_in_turn(tmp_path, "holding", release)
    cell = ScriptedArmCell(release, opening=0.09)  # at the release pose, the fingers already open
    journal = _resume(store, cell)
    assert journal["turns_deg"] == [0.0, 30.0] and journal["view"] == 1
    assert ("plan",) not in cell.asked and not any(a[0] == "gripper" and a[1] == 0.0 for a in cell.asked)
    assert journal["turn_intent"] is None and journal["holding"] is False
    assert journal["status"] == "failed" and journal["error"]["state"] == "scan"  # went on to scan view 1


def test_a_kill_between_moving_the_view_aside_and_saving_the_journal(tmp_path, monkeypatch):
    store = SessionStore(tmp_path)
    acq = Acquisition(ScriptedArmCell(np.eye(4), 0.1), store, AcquisitionConfig(views=3))  # type: ignore[arg-type]
    acq.j.update(state="register", view=0)
    store.save_journal(acq.j.to_dict())
    (tmp_path / "view_00" / "scan_0").mkdir(parents=True)
    (tmp_path / "view_00" / "scan_0" / "meta.json").write_text("{}")

    class Killed(BaseException):
        pass

    real_move = shutil.move

    def move_then_die(src, dst):  # noqa: ANN001, ANN202 - the kill lands right after the move
        real_move(src, dst)
        raise Killed

    monkeypatch.setattr(shutil, "move", move_then_die)
    with pytest.raises(Killed):
        asyncio.run(acq._rescan(0, "registration failed"))
    monkeypatch.undo()
    resumed = Acquisition(ScriptedArmCell(np.eye(4), 0.1), SessionStore(tmp_path), AcquisitionConfig())  # type: ignore[arg-type]
    assert resumed.state == State.SCAN and resumed.view == 0
    assert (tmp_path / "view_00_attempt1" / "scan_0" / "meta.json").is_file()
    assert not (tmp_path / "view_00").exists()

"""Replay driver: reports recorded joint states and refuses every motion.

States come from an array (N, 6) or from a session folder's per-scan ``joints`` entries in meta.json
(written by the orchestrator: a list of 6 values, or a dict with ``position``/``q`` and optionally
``gripper_opening``). ``seek(i)`` / ``advance()`` choose which recorded state ``read_joints`` reports.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.session_folder import read_session, scan_dir
from services.arm.drivers.base import ArmDriver
from services.arm.errors import BadCommand, ReadOnlyDriver


class ReplayArmDriver(ArmDriver):
    name = "replay"

    def __init__(self, states: np.ndarray, openings: np.ndarray | None = None, labels: list[str] | None = None):
        Q = np.asarray(states, dtype=np.float64)
        if Q.ndim != 2 or Q.shape[1] != 6 or Q.shape[0] == 0 or not np.all(np.isfinite(Q)):
            raise BadCommand(
                "recorded states must be a non-empty finite (N, 6) array",
                code="bad_shape",
                detail={"shape": list(Q.shape)},
            )
        self.states = Q
        self.openings = np.zeros(len(Q)) if openings is None else np.asarray(openings, dtype=np.float64)
        self.labels = labels or [str(i) for i in range(len(Q))]
        self.index = 0

    @classmethod
    def from_session(cls, session: Path) -> ReplayArmDriver:
        """All scans' recorded joints, in view then scan order; scans without ``joints`` are skipped."""
        info = read_session(Path(session))
        states, openings, labels = [], [], []
        for v in info.views:
            view = int(v["index"])
            for scan in info.scans(view):
                meta = json.loads((scan_dir(info.path, view, scan) / "meta.json").read_text())
                j = meta.get("joints")
                if j is None:
                    continue
                if isinstance(j, dict):
                    pos = j.get("position", j.get("q"))
                    opening = float(j.get("gripper_opening", 0.0))
                else:
                    pos, opening = j, 0.0
                states.append(np.asarray(pos, dtype=np.float64).reshape(6))
                openings.append(opening)
                labels.append(f"view_{view:02d}/scan_{scan}")
        if not states:
            raise BadCommand(f"no scan in {session} records joints", code="no_joints")
        return cls(np.array(states), np.array(openings), labels)

    def seek(self, index: int) -> None:
        if not 0 <= index < len(self.states):
            raise BadCommand("replay index out of range", code="bad_value", detail={"n": len(self.states)})
        self.index = int(index)

    def advance(self) -> bool:
        """Move to the next recorded state; False at the end (stays on the last)."""
        if self.index + 1 < len(self.states):
            self.index += 1
            return True
        return False

    read_only = True

    @property
    def home_q(self) -> np.ndarray:
        return self.states[0].copy()

    def home(self) -> None:
        """Home on a replay: back to the first recorded state."""
        self.seek(0)

    def connect(self) -> None:
        return None

    def close(self) -> None:
        return None

    def read_joints(self) -> np.ndarray:
        return self.states[self.index].copy()

    def read_gripper(self) -> float:
        return float(self.openings[self.index])

    def _refuse(self, what: str) -> None:
        raise ReadOnlyDriver(f"the replay driver reports recorded states and cannot {what}")

    def write_setpoint(self, q: np.ndarray) -> None:
        self._refuse("move")

    def set_gripper(self, opening_m: float, force: float) -> None:
        self._refuse("drive the gripper")

    def torque(self, on: bool) -> None:
        if on:
            self._refuse("enable torque")

    def stop(self) -> None:
        return None

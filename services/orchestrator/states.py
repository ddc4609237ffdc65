"""The acquisition's states and the transitions allowed between them (drawn in docs/orchestrator.md).

Their own module so the parts the state machine calls (the turn journal) name a state the same way the
machine does, without importing the machine.
"""

from __future__ import annotations

from enum import StrEnum


class State(StrEnum):
    LOCATE = "locate"
    SCAN = "scan"
    REGISTER = "register"
    PLAN_GRASP = "plan_grasp"
    TURN = "turn"
    MODEL = "model"
    DONE = "done"
    FAILED = "failed"
    STOPPED = "stopped"


TRANSITIONS: dict[State, set[State]] = {
    State.LOCATE: {State.SCAN},
    State.SCAN: {State.REGISTER},
    State.REGISTER: {State.PLAN_GRASP, State.MODEL, State.SCAN},
    State.PLAN_GRASP: {State.TURN, State.SCAN},
    State.TURN: {State.SCAN, State.PLAN_GRASP},
    State.MODEL: {State.DONE},
}
TERMINAL = {State.DONE, State.FAILED, State.STOPPED}

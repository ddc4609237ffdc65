"""Zenoh key expressions, in one place so no service spells a key by hand.

Robot-scoped keys carry ``{robot}`` (default ``robot0``) so several cells can share one Zenoh network;
compute services (registration, grasp) are shared by all cells. Every service instance answers
``objscan/{service}/{instance}/health`` and holds the liveliness token ``objscan/@alive/{service}/{instance}``
(``@alive`` is a verbatim chunk: wildcards elsewhere never match it by accident).
"""

from __future__ import annotations

DEFAULT_ROBOT = "robot0"
ROOT = "objscan"

ALIVE_PREFIX = f"{ROOT}/@alive"
ALL_ALIVE = f"{ALIVE_PREFIX}/**"


def alive(service: str, instance: str) -> str:
    return f"{ALIVE_PREFIX}/{service}/{instance}"


def health(service: str, instance: str) -> str:
    return f"{ROOT}/{service}/{instance}/health"


def parse_alive(key: str) -> tuple[str, str] | None:
    """(service, instance) of a liveliness key, or None when it is not one of ours."""
    parts = key.split("/")
    if len(parts) == 4 and parts[0] == ROOT and parts[1] == "@alive":
        return parts[2], parts[3]
    return None


# camera
def camera_capture(robot: str = DEFAULT_ROBOT) -> str:
    return f"{ROOT}/{robot}/camera/capture"


# arm
def arm(robot: str, op: str) -> str:
    """``op`` is one of state, move, gripper, stop, scene, ik."""
    return f"{ROOT}/{robot}/arm/{op}"


# sim (digital twin)
def sim(robot: str, op: str) -> str:
    """``op``: render, joints, gripper, world, reset, fault, ..."""
    return f"{ROOT}/{robot}/sim/{op}"


# registration (shared compute)
REGISTRATION_STATIC = f"{ROOT}/registration/static"
REGISTRATION_PAIR = f"{ROOT}/registration/pair"
REGISTRATION_EDGE = f"{ROOT}/registration/edge"
REGISTRATION_DYNAMIC = f"{ROOT}/registration/dynamic"


def registration_worker_pair(instance: str) -> str:
    """A pair job addressed to one registration worker (the dispatcher picks workers by liveliness)."""
    return f"{ROOT}/registration/worker/{instance}/pair"


GRASP_PLAN = f"{ROOT}/grasp/plan"


def orchestrator(robot: str, op: str) -> str:
    """``op``: run, status, stop."""
    return f"{ROOT}/{robot}/orchestrator/{op}"

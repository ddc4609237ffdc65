"""Where the arm can work, as plain numbers: its TCP workspace box and the ring of the table it grasps on.

Kept apart from ``safety.py`` (which needs the kinematics) so that a config validator — the acquisition's
``workspace_center``, ``objscan scan --workspace-center`` — checks a place against the same facts the arm's
safety envelope and the set-down planner use, without loading the robot model.
"""

from __future__ import annotations

import math

WORKSPACE_MIN: tuple[float, float, float] = (-0.35, -0.6, 0.0)
"""Lower corner (m, in ``base``) of the box the TCP must stay in (the safety envelope's default)."""
WORKSPACE_MAX: tuple[float, float, float] = (0.85, 0.6, 0.9)
"""Upper corner (m, in ``base``) of that box."""

TABLE_RADIUS_M: tuple[float, float] = (0.25, 0.9)
"""Distances (m) from the arm's base at which an object can stand to be grasped, turned and set down: nearer,
the hand folds onto the base; farther, the arm reaches the object only stretched flat."""


def table_reach_problem(x: float, y: float) -> str | None:
    """Why an object standing at (x, y) on the table (m, ``base``) is out of the arm's reach, or None."""
    r = math.hypot(x, y)
    lo, hi = TABLE_RADIUS_M
    if not lo <= r <= hi:
        return f"{r:.3f} m from the arm's base, outside its reach of {lo}-{hi} m"
    if not (WORKSPACE_MIN[0] <= x <= WORKSPACE_MAX[0] and WORKSPACE_MIN[1] <= y <= WORKSPACE_MAX[1]):
        return (f"outside the arm's workspace box x [{WORKSPACE_MIN[0]}, {WORKSPACE_MAX[0]}] m, "
                f"y [{WORKSPACE_MIN[1]}, {WORKSPACE_MAX[1]}] m")
    return None

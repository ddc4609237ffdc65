"""Repositioning: a pick-and-place without a turn that brings the object back to a spot where the arm works
well, before the views go on. Plain functions over poses, so each is tested without a robot.

Why: relocated set-downs (``regrasp.py``), slips and pushes at the set-down move the object around the table.
Measured in whole MuJoCo acquisitions: a squat can relocated five times drifted out to where, at view 10 of
12, every grasp, turn and set-down hit joint limits and the run ended. Nothing brought it back. The spots
the kinematics favour are known: the workspace centre, where every acquisition starts and its scan poses
are planned, and the near ring of ``RelocationConfig`` (0.40 m from the base, where a top-down turn reaches
every yaw). An object farther than ``RelocationConfig.reposition_drift`` from all of them is picked and set
down, unturned, at the nearest one it can be scanned at; the view is then scanned there again (its old
frames are kept aside), so the turn bookkeeping is untouched: no view is added and no turn is counted.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from services.orchestrator.config import RelocationConfig
from services.orchestrator.planning import TurnPoses

#: ``TurnPoses.direction`` of a pick-and-place that does not turn the object.
NO_TURN = 0


def favoured_spots(workspace_center: np.ndarray, config: RelocationConfig) -> list[np.ndarray]:
    """The spots (x, y, 0) the arm works best at: the workspace centre, then the near ring's spots."""
    c = np.asarray(workspace_center, float)[:2]
    out = [np.array([c[0], c[1], 0.0])]
    for a in config.azimuths_deg:
        p = config.near_radius * np.array([np.cos(np.radians(a)), np.sin(np.radians(a))])
        if not any(np.allclose(p, o[:2], atol=1e-3) for o in out):
            out.append(np.array([p[0], p[1], 0.0]))
    return out


def drift(center: np.ndarray, spots: list[np.ndarray]) -> float:
    """Distance (m, in the table plane) from the object's centre to the nearest favoured spot."""
    c = np.asarray(center, float)[:2]
    return min(float(np.linalg.norm(c - s[:2])) for s in spots) if spots else 0.0


def reposition_shifts(center: np.ndarray, spots: list[np.ndarray], min_shift: float) -> list[np.ndarray]:
    """Shifts (x, y, 0) from the object's centre to each favoured spot, nearest first, leaving out the spot
    it already stands at."""
    c = np.asarray(center, float)[:2]
    out = [np.array([*(s[:2] - c), 0.0]) for s in spots]
    return sorted((d for d in out if np.linalg.norm(d) >= min_shift), key=lambda d: float(np.linalg.norm(d)))


def without_turn(seq: TurnPoses) -> TurnPoses:
    """The pick of ``seq`` and a set-down where it was picked, without turning: lift, lower, release, back
    off the way the hand came. Carried elsewhere with ``regrasp.relocated``."""
    return replace(seq, name=f"{seq.name}_reposition", turned_lifted=seq.lifted.copy(), turned=seq.grasp.copy(),
                   retreat=seq.pregrasp.copy(), above_retreat=seq.above_pregrasp.copy(), direction=NO_TURN,
                   carry_from=None)

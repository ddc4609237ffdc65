"""Will a grasp hold the object while it is lifted, turned and set down? A torque and force budget from the
gripper's force and the pads' friction: the same values the twin's MuJoCo model uses
(``services/sim/physics.PhysicsConfig``; a test keeps the two equal).

Two pads squeeze with ``grip_force`` each. They carry the weight by sliding friction (``pad_friction``:
2 mu F against m g) and resist the object pivoting about the grasp line by torsional friction
(``torsional_friction`` is MuJoCo's patch radius: 2 mu_t F N m). Gravity pivots the object about the line
when its centre of mass lies beside it, and the motions swing it when the centre lies far below or above
the line: a tall object gripped high, or a lying bottle gripped off its middle, tips in the hand and topples
at the set-down. ``hold_ratio`` is the larger of the two loads over its budget: below 1 the grasp holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G = 9.81


@dataclass(frozen=True)
class HoldModel:
    """Gripper and contact values of the hold budget (defaults: the twin's physics)."""

    grip_force: float = 25.0  # N per pad when closed (the current limit)
    pad_friction: float = 1.0  # sliding friction of the pads (the larger of a contact pair's wins)
    torsional_friction: float = 0.004  # m: the pads' resistance to spinning about their normal
    density: float = 400.0  # kg/m^3 over the object's closed volume, for a mass estimate
    swing_accel: float = 1.5  # m/s^2: the hand's accelerations and a few degrees of tilt during a turn


def estimate_mass(footprint: tuple[float, float], height: float, model: HoldModel | None = None) -> float:
    """Mass (kg) of an object filling most of its box (``footprint`` lengths x ``height``) at the model's
    density: a box fills it, a cylinder pi/4 of it; the mean is taken."""
    m = model or HoldModel()
    return float(m.density * footprint[0] * footprint[1] * height * 0.9)


def hold_ratio(contacts: np.ndarray, com: np.ndarray, mass: float, model: HoldModel | None = None) -> float:
    """Load over budget for a grasp closing on ``contacts`` (2 x 3, base frame) of an object of ``mass`` with
    its centre of mass at ``com``: max(weight / sliding budget, pivot torque / torsional budget)."""
    m = model or HoldModel()
    p = np.asarray(contacts, float)
    line = p[1] - p[0]
    n = float(np.linalg.norm(line))
    if n < 1e-9:
        return float("inf")
    u = line / n
    r = np.asarray(com, float) - 0.5 * (p[0] + p[1])
    static = abs(float(np.cross(r, [0.0, 0.0, -mass * G]) @ u))
    # the swing: accelerations across the line act at the centre of mass's distance from it
    off = r - (r @ u) * u
    swing = mass * m.swing_accel * float(np.linalg.norm(off))
    torque_budget = 2.0 * m.torsional_friction * m.grip_force
    force_budget = 2.0 * m.pad_friction * m.grip_force
    return max(mass * G / force_budget, (static + swing) / torque_budget)

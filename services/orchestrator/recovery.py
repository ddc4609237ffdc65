"""Which grasps to plan and try first when the object lies down or a grasp slipped: plain functions, so each
choice is tested without a robot.

Why: the planner's ``auto`` mode plans top-down grasps only when no frontal one exists. A tall bottle that
toppled and lies on its side still offers one frontal grasp (across its body, approached from the side),
which the arm rarely reaches; the top-down grasps across the lying body, the easy ones, were planned only
after every frontal chain had failed, and the re-scan budget often ran out first. So a lying object (after
a topple, or whenever its footprint is much longer than it is tall) gets frontal and top-down grasps
planned alike, top-down first. (Only after a topple: an object that stands as it was placed keeps the
order its views so far were turned with.)

After a slip the same grasp height and kind tends to slip again: the next plan offers both kinds, the
kind that did not slip first, and among the others the grasp whose line passes nearest the estimated
centre of mass first (``services/grasp/hold.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common.messages import Grasp
from services.grasp.hold import HoldModel, estimate_mass, hold_ratio

#: A footprint at least this many times longer than the object is tall: the object lies down.
LYING_RATIO = 1.6


def footprint_length(xyz: np.ndarray) -> float:
    """Longest horizontal extent of an object cloud (m), along its principal horizontal direction."""
    xy = np.asarray(xyz, float)[:, :2]
    if len(xy) < 3:
        return 0.0
    centred = xy - xy.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    along = centred @ vecs[:, -1]
    return float(np.quantile(along, 0.995) - np.quantile(along, 0.005))


def lies_down(xyz: np.ndarray, height: float) -> bool:
    """Whether an object that toppled now lies on its side: its footprint is far longer than it is tall
    (a bottle or a tall box on its side, not one that landed on its other end)."""
    return height > 0 and footprint_length(xyz) >= LYING_RATIO * height


def plan_mode(grasp_mode: str, lying: bool, slipped: list[str]) -> str:
    """The planner mode for the next plan: the machine's own (``auto`` or ``top_down``) unless the object
    lies down or a grasp of this view slipped, then frontal and top-down alike (``both``)."""
    if grasp_mode == "auto" and (lying or slipped):
        return "both"
    return grasp_mode


def grasp_order(grasps: list[Grasp], lying: bool, slipped: list[str], xyz: np.ndarray, center: np.ndarray,
                height: float, side_approach: list[bool] | None = None, model: HoldModel | None = None
                ) -> list[int]:
    """Indices of ``grasps`` in the order to try them, for an object cloud ``xyz`` whose footprint centre is
    ``center`` and top ``height``.

    - a kind that slipped at this view goes after the kinds that did not;
    - a lying object: top-down grasps before frontal ones;
    - grasps approached from the side (``side_approach``) after the radial-ish ones: the arm reaches far
      low poses only roughly radially;
    - then the grasps that hold best against the estimated centre of mass (``hold_ratio``: gravity and swing
      torque about the grasp line over what the pads' friction resists; in steps of 0.25 so that near-equal
      grasps keep the planner's order);
    - after a slip, lower grasps first;
    - the planner's order breaks ties.
    """
    hold = model or HoldModel()
    pts = np.asarray(xyz, float)
    com = np.array([float(center[0]), float(center[1]), 0.5 * float(height)])
    span = np.ptp(pts[:, :2], axis=0) if len(pts) else np.zeros(2)
    mass = estimate_mass((float(span[0]), float(span[1])), float(height), hold)

    def key(i: int) -> tuple[Any, ...]:
        g = grasps[i]
        ratio = hold_ratio(np.asarray(g.contacts, float), com, mass, hold)
        side = bool(side_approach[i]) if side_approach is not None else False
        lower = float(np.asarray(g.contacts, float)[:, 2].mean()) if slipped else 0.0
        return (g.kind in slipped, lying and g.kind != "top_down", side, int(ratio / 0.25), round(lower, 3), i)

    return sorted(range(len(grasps)), key=key)

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

A tall object is gripped across two faces before it is gripped on an edge. The planner keeps pairs with one
contact on a vertical edge (from the arm's side a box turned 30 degrees shows one of the faces a grasp closes
on), and closing on an edge turns and pushes the object in the hand until a face lies on each pad: the line
it is then held on is not the planned one, and neither is its hold. Measured in a whole MuJoCo acquisition (a
box 6.9 x 9.3 x 17.1 cm, 0.63 kg): such a grasp (one contact normal 64 degrees off its line) turned it to view
5 and set it down 2.9 cm from where it stood; the same grasp at view 5 slipped as it lifted, the box fell over
and came to rest 0.73 m from the base, out of the arm's reach, and the run ended there. A two-face pair (one
face mirrored in when it was not seen) was planned at both views. A squat object that slips stays standing
and is re-grasped, so only a tall one (``TALL_RATIO``) has its edge grasps put last.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common.footprint import min_area_rectangle
from common.messages import Grasp
from services.grasp.hold import HoldModel, estimate_mass, hold_ratio
from services.grasp.stray import stray_mask

#: A footprint at least this many times longer than the object is tall: the object lies down.
LYING_RATIO = 1.6
#: An object at least this many times taller than its footprint is thin falls over when it slips out of the
#: pads (a box tips when its centre of mass passes its bottom edge: tilted by atan(1 / ratio), 34 degrees).
TALL_RATIO = 1.5
#: Degrees a contact's normal may lie off the grasp line before the contact is on an edge, not a face (the
#: planner's side-face angle: a face seen at more than that is not a face the pads close on).
EDGE_DEG = 30.0


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


def topples_if_dropped(xyz: np.ndarray, height: float) -> bool:
    """Whether the object is tall for its footprint (``TALL_RATIO`` times its thinnest side): a slip drops it
    over instead of back onto its base. Stray returns (``stray_mask``) are left out of the footprint: one
    speck beside a thin box would otherwise make it look squat."""
    pts = np.asarray(xyz, float)
    if height <= 0 or len(pts) < 3:
        return False
    kept = pts[~stray_mask(pts)]
    _, _, sides = min_area_rectangle((kept if len(kept) >= 3 else pts)[:, :2])
    thinnest = float(np.min(sides))
    return thinnest > 0 and height >= TALL_RATIO * thinnest


def on_an_edge(grasp: Grasp) -> bool:
    """Whether a grasp closes on an edge: one contact's normal (the planner's ``cos_alpha1``/``cos_alpha2``)
    lies more than ``EDGE_DEG`` off its line. Grasps without those metrics count as on faces."""
    cos = [float(grasp.metrics[k]) for k in ("cos_alpha1", "cos_alpha2") if k in grasp.metrics]
    return bool(cos) and min(cos) < float(np.cos(np.radians(EDGE_DEG)))


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
    - on a tall object (``topples_if_dropped``), grasps on an edge (``on_an_edge``) after those on two faces;
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
    tall = topples_if_dropped(pts, height)

    def key(i: int) -> tuple[Any, ...]:
        g = grasps[i]
        ratio = hold_ratio(np.asarray(g.contacts, float), com, mass, hold)
        side = bool(side_approach[i]) if side_approach is not None else False
        lower = float(np.asarray(g.contacts, float)[:, 2].mean()) if slipped else 0.0
        edge = tall and on_an_edge(g)
        return (g.kind in slipped, lying and g.kind != "top_down", side, edge, int(ratio / 0.25), round(lower, 3), i)

    return sorted(range(len(grasps)), key=key)

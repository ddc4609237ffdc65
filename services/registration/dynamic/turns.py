"""Do the model's views turn as the object was turned? The acceptance check that sees turns.

Why: the yaw about a body of revolution's own axis cannot be seen in its shape (nor in colour bands that are the
same all round). A pair stage that finds ~0 turn per edge for a cylinder gives a model whose views are stacked on
one side of the object: a partial arc that fits itself perfectly. Neither the posed fitness nor the loop closure
sees it: twelve corrections of -30 degrees compose to a full -360, the identity. What does see it is the turn
itself: view k stands in the model turned by its commanded cumulative turn plus a turn error, and the turn
accuracy (``turn_accuracy_deg`` of the session, 1 sigma per turn) bounds that error:

* **per turn**: between two consecutive kept views the model's turn minus the commanded one is within
  ``turn_sigmas`` sigma (times the square root of the number of turns between them, when a view was left out);
* **once round**: the model's views go round the object once, as the commanded turns do. Summed over the turns
  from the first view to the last (the loop edge is not a turn: it closes whatever the turns achieved), the
  corrections stay within half a revolution; stacked views sum to about minus one whole revolution.

The figures are reported (``consistency.turns``) and a miss is a ``why`` of an unaccepted model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.geometry import yaw_deg_about


@dataclass
class TurnCheck:
    """Per-view yaw corrections in the model and the turns' verdict."""

    corrections_deg: list[float]  # per kept view: model yaw minus commanded turn, relative to the first kept view
    edges: list[dict]  # per consecutive pair of kept views: its correction and the window it must be within
    total_correction_deg: float  # summed over the turns from the first kept view to the last
    misses: list[str]

    def to_json(self) -> dict:
        return {"corrections_deg": [round(c, 2) for c in self.corrections_deg], "edges": self.edges,
                "total_correction_deg": round(self.total_correction_deg, 2), "misses": list(self.misses)}


def _wrap(deg: float) -> float:
    """An angle in degrees into [-180, 180)."""
    return float((deg + 180.0) % 360.0 - 180.0)


def check_turns(poses: list[np.ndarray], axis: np.ndarray, kept: list[int], sigma_deg: float,
                sigmas: float, names: list[int] | None = None) -> TurnCheck:
    """Judge the model's turns: ``poses[k]`` is view k's pose in the pre-rotated frames (the commanded turn
    already undone, so its yaw about ``axis`` is the view's turn error); ``kept`` the positions fused;
    ``names`` the view index at each position (default: the position)."""
    kept = sorted(kept)
    name = (lambda k: names[k]) if names is not None else (lambda k: k)
    if len(kept) < 2:
        return TurnCheck([], [], 0.0, [])
    R0 = np.asarray(poses[kept[0]])[:3, :3]
    corr = [yaw_deg_about(axis, R0.T @ np.asarray(poses[k])[:3, :3]) for k in kept]
    edges, total, misses = [], 0.0, []
    pairs = list(zip(kept, corr, strict=True))
    for (i, a), (j, b) in zip(pairs[:-1], pairs[1:], strict=True):
        e = _wrap(b - a)
        window = sigmas * sigma_deg * float(np.sqrt(j - i))
        total += e
        edges.append({"from": name(i), "to": name(j), "correction_deg": round(e, 2), "window_deg": round(window, 2)})
    off = [e for e in edges if abs(e["correction_deg"]) > e["window_deg"]]
    if off:
        worst = max(off, key=lambda e: abs(e["correction_deg"]) / e["window_deg"])
        misses.append(f"{len(off)} of {len(edges)} turns in the model off the commanded turn beyond "
                      f"{sigmas:g} x the turn accuracy {sigma_deg:g} deg (worst {worst['correction_deg']:+.1f} deg, "
                      f"view {worst['from']} to {worst['to']})")
    if abs(total) >= 180.0:
        misses.append(f"the views do not go round the object once: their turns add up to {total:+.0f} deg off "
                      "the commanded ones (views stacked on one side, a turn not observable from the shape)")
    return TurnCheck(corr, edges, total, misses)


def imported_turn_misses(session_data: dict) -> list[str]:
    """Why a model of an imported sequence cannot be accepted whatever its own figures: the import found its
    turns unsure (look-alike turns of a symmetric or low-texture object, little overlap, estimates the loop
    contradicts; ``importer/turn_graph.py``). A model built on unsure turns may fit itself perfectly with
    its views stacked wrongly, so it must say so instead of claiming to be right."""
    turns = (session_data.get("import") or {}).get("turns") or {}
    if turns.get("status") != "unsure":
        return []
    loop = turns.get("loop") or {}
    reasons = loop.get("reasons") or ["the import's turn estimates are unsure"]
    pairs = [f"{p['from']}->{p['to']}" for p in loop.get("unsure_pairs", [])]
    tail = f" (unsure pairs {', '.join(pairs[:8])}{', ...' if len(pairs) > 8 else ''})" if pairs else ""
    return [f"the imported turns are unsure: {'; '.join(reasons)}{tail}"]

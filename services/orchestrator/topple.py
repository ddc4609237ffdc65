"""Noticing that the object toppled at a set-down: its height above the table changed between views.

A turn about the table normal keeps the object's height; a set-down that leaves it on its side (a tall thin
box, physics mode of the twin, or a real cell) changes it. Registering the new view against the old ones
would fuse two different resting poses as if they were one turn apart, so the state machine restarts the
views from where the object now lies instead (``Acquisition._restart_after_topple``).
"""

from __future__ import annotations


def topple_reason(previous_height: float | None, height: float, tolerance_m: float, tolerance_rel: float,
                  view: int) -> str | None:
    """Why view ``view`` looks toppled (its height differs from the previous view's by more than
    ``max(tolerance_m, tolerance_rel * previous)``), or None when it does not."""
    if previous_height is None or previous_height <= 0:
        return None
    tol = max(tolerance_m, tolerance_rel * previous_height)
    if abs(height - previous_height) <= tol:
        return None
    return (f"the object's height changed from {previous_height * 1000:.0f} mm to {height * 1000:.0f} mm "
            f"between views {view - 1} and {view} (more than {tol * 1000:.0f} mm): it toppled or fell over at "
            "the set-down")

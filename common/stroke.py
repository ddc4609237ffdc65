"""When a grasp is near the gripper's stroke: the one test the grasp planner and the orchestrator share.

A parallel gripper opened to its whole stroke clears an object ``width`` wide by half the difference a side.
Under about 5 mm a side that room is mostly taken by the camera's location error (the hand-eye and joint
noise put the object 2-3 mm off on the twin's robot profile), so such a grasp is planned and opened with
care: on its faces and level (``services/grasp/near_stroke.py``) and the whole stroke open
(``services/orchestrator/motion.pick_opening``).
"""

from __future__ import annotations

#: m the whole stroke of the RH-P12-RN(A) on PAPRAS.
STROKE = 0.106
#: m a side the fully open pads clear a grasp's width under which the grasp is near the stroke.
NEAR_STROKE_SIDE = 0.005


def near_stroke(width: float, stroke: float = STROKE, side: float = NEAR_STROKE_SIDE) -> bool:
    """Whether pads open ``stroke`` apart clear an object ``width`` wide by under ``side`` a side."""
    return 0.5 * (stroke - float(width)) < side

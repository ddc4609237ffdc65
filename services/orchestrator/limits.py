"""Naming the limit that stopped an acquisition: reach, gripper stroke, no collision-free grasp, or grasps
that did not hold.

When a view runs out of re-scans, "no executable grasp" alone does not tell a user whether their object
is too wide for the gripper, too low for the pads, or out of the arm's reach. The state machine keeps, per
view, the planner's rejection counts, the arm's dry-run refusal codes and the grasp outcomes; this module
turns them into one sentence naming the dominant limit, with the counts behind it.
"""

from __future__ import annotations

from collections import Counter

#: Arm refusal codes (services/arm) that mean the pose or the straight line to it is out of reach.
REACH_CODES = frozenset({"unreachable", "line_unreachable", "line_discontinuous", "out_of_envelope", "workspace",
                         "joint_limit", "joint_limits", "singular", "tcp_height"})
#: Arm refusal codes that mean the hand or the held object would hit something.
COLLISION_CODES = frozenset({"collision"})
#: Arm answers that are not a refusal of the motion asked for: the arm is e-stopped or still moving. Trying the
#: next candidate cannot help, so they end any search over alternatives and propagate to the state machine.
ARM_UNAVAILABLE_CODES = frozenset({"estop_latched", "busy"})
#: Planner rejections that mean the gripper's stroke (or its pads' length) does not fit the object.
STROKE_REJECTIONS = frozenset({"too_wide", "too_short_for_frontal"})
#: Planner rejections that mean every candidate would collide with the table or the object.
COLLISION_REJECTIONS = frozenset({"collides_with_table", "collides_with_object"})


def _fmt(c: Counter) -> str:
    return ", ".join(f"{k} x{v}" for k, v in c.most_common(4))


def name_limit(planner_rejections: dict[str, int], dry_run_codes: list[str], grasp_failures: list[str],
               max_opening_mm: float = 106.0) -> str:
    """The limit that best explains a view without an executable grasp, as "<limit>: <why> (<counts>)"."""
    rej = Counter({k: int(v) for k, v in planner_rejections.items() if int(v) > 0})
    dry = Counter(dry_run_codes)
    held = Counter(grasp_failures)
    reach = sum(v for k, v in dry.items() if k in REACH_CODES)
    collide = sum(v for k, v in dry.items() if k in COLLISION_CODES)
    stroke = sum(v for k, v in rej.items() if k in STROKE_REJECTIONS)
    table = sum(v for k, v in rej.items() if k in COLLISION_REJECTIONS)
    if held:
        return f"grasps did not hold: every executed grasp failed on contact ({_fmt(held)})"
    if dry and reach >= collide:
        return f"reach: every planned grasp, turn or set-down leaves the arm's reachable workspace ({_fmt(dry)})"
    if dry:
        return f"no collision-free grasp: the hand or the held object would hit the cell ({_fmt(dry)})"
    if stroke and stroke >= table:
        return (f"gripper stroke: the object is wider than the gripper opens ({max_opening_mm:.0f} mm) or too "
                f"short for the pads across every graspable pair of faces ({_fmt(rej)})")
    if table:
        return f"no collision-free grasp: every candidate's pads hit the table or the object ({_fmt(rej)})"
    if rej:
        return f"no grasp: no pair of faces the gripper can close on ({_fmt(rej)})"
    return "no grasp: the planner found no candidate on the isolated object"


def name_scan_pose_limit(dry_run_codes: list[str]) -> str:
    """The limit behind a view with no reachable set of scan poses: the camera cannot be brought around the
    object where it stands (too far, too close to the base, or the camera would hit the cell): reach."""
    return (f"reach: no set of scan poses around the object is reachable where it stands "
            f"({_fmt(Counter(dry_run_codes)) or 'no candidate poses'})")

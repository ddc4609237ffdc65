"""Pure geometry of an acquisition: where the camera goes, and the poses of one pick-turn-place.

No I/O here, so the choices can be tested and reasoned about without a robot.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from common.geometry import look_at
from common.messages import Grasp
from services.orchestrator.config import ScanGeometry, TurnMotion

#: m the open fingers' tips reach ahead of the TCP along the approach (the pads, 4 cm long, centred on it).
FINGER_TIP = 0.02
#: m the open fingers' tips stand out of the object's collision box at a pre-grasp that had to back off.
PREGRASP_CLEARANCE = 0.01

def camera_pose_looking_at(target: np.ndarray, distance: float, elevation_deg: float, azimuth_deg: float
                           ) -> np.ndarray:
    """T_base_camera at ``distance`` from ``target``, ``elevation`` above its horizon, image upright."""
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    eye = np.asarray(target, dtype=float) + distance * np.array(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return look_at(eye, target, (0.0, 0.0, 1.0))


def arm_side_azimuth_deg(center: np.ndarray) -> float:
    """Azimuth (deg, about base z) from the object toward the arm base: the side the camera can reach."""
    return float(np.degrees(np.arctan2(-center[1], -center[0])))


def scan_pose_candidates(center: np.ndarray, height: float, geometry: ScanGeometry) -> list[list[np.ndarray]]:
    """Sets of 3 scan poses (T_base_camera) around the object, most preferred first."""
    target = np.array([center[0], center[1], max(height, 0.02) * 0.5])
    base_az = arm_side_azimuth_deg(center)
    sets = []
    for distance in geometry.distances:
        for elevation in geometry.elevations_deg:
            sets.append([camera_pose_looking_at(target, distance, elevation, base_az + off)
                         for off in geometry.azimuth_offsets_deg])
    return sets


def look_pose(center_guess: np.ndarray, geometry: ScanGeometry) -> np.ndarray:
    """The locate pose: looking at where the object should be, from high enough to see the table."""
    target = np.array([center_guess[0], center_guess[1], 0.05])
    return camera_pose_looking_at(target, geometry.look_distance, geometry.look_elevation_deg,
                                  arm_side_azimuth_deg(center_guess))


@dataclass
class TurnPoses:
    """The T_base_gripper waypoints of one pick-turn-place with a given angular offset of a grasp."""

    name: str
    above_pregrasp: np.ndarray
    pregrasp: np.ndarray
    grasp: np.ndarray
    lifted: np.ndarray
    turned_lifted: np.ndarray
    turned: np.ndarray
    retreat: np.ndarray
    above_retreat: np.ndarray
    direction: int = 1  # +1: the planner's turn (counter-clockwise seen from above); -1: the mirror turn
    carry_from: np.ndarray | None = None  # a relocated set-down: where the turn ends before the carry (regrasp.py)
    low_above: bool = False  # ``above_*`` at ``TurnMotion.low_clearance``: tried after every other chain

    def straight_moves(self, center: np.ndarray) -> list[ChainMove]:
        """Every move after ``above_pregrasp``, in order: all straight lines, so that once the arm stands at
        ``above_pregrasp`` the joint path of the whole pick-turn-place is fixed (each line's dense IK
        continues the previous one's branch) and can be checked in full before the hand sets off."""
        moves = [ChainMove("down to pre-grasp", self.pregrasp, "approach", contact=False),
                 ChainMove("approach", self.grasp, "approach"),
                 ChainMove("lift", self.lifted, "held")]
        arc_end = self.turned_lifted if self.carry_from is None else self.carry_from
        moves += [ChainMove("turn", w, "held") for w in turn_arc(self.lifted, arc_end, center)]
        if self.carry_from is not None:  # the object carried, lifted, to where it is set down
            moves += [ChainMove("carry", w, "held") for w in carry_line(self.carry_from, self.turned_lifted)]
        moves += [ChainMove("set down", self.turned, "held"),
                  ChainMove("retreat", self.retreat, "released"),
                  ChainMove("up", self.above_retreat, "released")]
        return moves


@dataclass
class ChainMove:
    """One straight-line move of a pick-turn-place: where to, in which phase, whether the pads may touch."""

    step: str
    target: np.ndarray
    phase: str  # approach (gripper open, before closing) | held | released
    contact: bool = True
    #: a joint-space move to ``target`` (the IK nearest the configuration before it) instead of a straight line:
    #: a short chord of an arc that passes the wrist's singularity (joint 5 at 0), where a straight line's dense
    #: IK turns joints 4 and 6 half a turn; a joint move passes it with joint 5 alone (``lay_down._tipped``)
    joint: bool = False


def _lift(T: np.ndarray, dz: float) -> np.ndarray:
    out = T.copy()
    out[2, 3] += dz
    return out


def clear_pregrasp(pre: np.ndarray, grasp: np.ndarray, box: tuple[np.ndarray, np.ndarray],
                   footprint: np.ndarray, margin: float, opening: float,
                   tip: float = FINGER_TIP, clearance: float = PREGRASP_CLEARANCE) -> np.ndarray:
    """``pre`` moved back along the approach until the open fingers' tips are ``clearance`` out of the object's
    collision ``box`` (centre, extent: axis-aligned, grown by ``margin``), when the object itself, grown by
    ``margin``, is wider across the closing axis than the fingers are open (``opening``).

    Why: the pre-grasp stands a finger length back from the grasp, which leaves the open fingers reaching
    beside the object; for an object nearly as wide as the stroke (9.9 cm of 10.6) its collision box then
    holds them, and the arm refuses the way down to the pre-grasp. From far enough back the fingers come in
    along the approach, where contact is allowed. ``footprint``: the object's points on the table (x, y),
    whose extent across the closing axis (0.5 % of them either side left out: strays) is its width there; an
    object the fingers clear keeps its pre-grasp."""
    y = np.asarray(grasp[:3, 1], float)[:2]
    along = np.asarray(footprint, float) @ y
    across = float(np.quantile(along, 0.995) - np.quantile(along, 0.005)) + 2.0 * margin
    if across <= opening:
        return pre
    c, e = np.asarray(box[0], float), np.asarray(box[1], float)
    x = grasp[:3, 0]
    corners = c + 0.5 * e * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    near = float(np.min((corners - grasp[:3, 3]) @ x))  # the box's nearest extent along the approach
    back = max(float((grasp[:3, 3] - pre[:3, 3]) @ x), tip + clearance - near)
    out = pre.copy()
    out[:3, 3] = grasp[:3, 3] - back * x
    return out


def turn_sequences(grasp: Grasp, motion: TurnMotion, object_height: float,
                   clear: tuple[tuple[np.ndarray, np.ndarray], np.ndarray, float] | None = None
                   ) -> list[TurnPoses]:
    """For each angular offset of ``grasp`` (likeliest first), its full pick-turn-place waypoints; then the
    same with the turn mirrored (-30°), for when the arm cannot follow the planner's direction.

    Frontal offsets go in the planner's order (0, ±15). Top-down ones go from the most tilted toward the
    arm's base to the most tilted away: at the object's 0.60 m the PAPRAS wrist cannot point straight down
    (IK: unreachable for every height from 0.10 to 0.30 m), only approaches leaning 30-45° toward the base
    reach it (``_base_side_first``).

    The turn poses come from the planner (turn about the table normal through the object's centre); the
    retreat backs off from the turned grasp as far as the pre-grasp was from the grasp. Without a motion
    planner, joint-space moves happen only high above the object (``above_*``: ``clearance`` over its
    top); near the object the hand moves on straight lines. With ``clear`` (the object's collision box, its
    points' (x, y), and the gripper's opening for this grasp), a pre-grasp whose open fingers the
    object's box would hold stands back until they are clear of it (``clear_pregrasp``, the box's margin
    ``motion.object_box_margin``).

    A top-down grasp's chains come a second time with ``above_*`` at ``motion.low_clearance`` (``low_above``,
    names ending ``_low``), for where the hand pointing down does not reach ``clearance`` above the object (the
    near ring); the state machine tries them after every other chain.
    """
    safe_z = object_height + motion.clearance
    poses = {name: p.matrix() for name, p in grasp.poses.items()}
    order = _base_side_first if grasp.kind == "top_down" else _offset_order
    out: list[TurnPoses] = []
    for direction in (1, -1):
        for name in sorted((n for n in poses if n.startswith("grasp")), key=order):
            suffix = name[len("grasp"):]
            pre, turn = poses.get("pregrasp" + suffix), poses.get("turn" + suffix)
            if pre is None or turn is None:
                continue
            g = poses[name]
            if clear is not None:
                pre = clear_pregrasp(pre, g, clear[0], clear[1], motion.object_box_margin, clear[2])
            if direction < 0:  # the same turn about the same line, the other way round
                turn = np.linalg.inv(turn @ np.linalg.inv(g)) @ g
            back = pre[:3, 3] - g[:3, 3]
            retreat = turn.copy()
            retreat[:3, 3] = turn[:3, 3] + turn[:3, :3] @ (g[:3, :3].T @ back)
            out.append(TurnPoses(name=name if direction > 0 else f"{name}_reverse",
                                 above_pregrasp=_at_height(pre, safe_z), pregrasp=pre, grasp=g,
                                 lifted=_lift(g, motion.lift), turned_lifted=_lift(turn, motion.lift),
                                 turned=turn, retreat=retreat, above_retreat=_at_height(retreat, safe_z),
                                 direction=direction))
    if grasp.kind == "top_down" and motion.low_clearance < motion.clearance:
        low_z = object_height + motion.low_clearance
        out += [replace(sq, name=f"{sq.name}_low", above_pregrasp=_at_height(sq.pregrasp, low_z),
                        above_retreat=_at_height(sq.retreat, low_z), low_above=True) for sq in list(out)]
    return out


def carry_line(start: np.ndarray, end: np.ndarray, step: float = 0.05) -> list[np.ndarray]:
    """Waypoints of a straight carry at constant orientation, at most ``step`` apart: each short line's
    dense IK continues the previous one's branch, where one long line can end on another branch."""
    n = max(1, int(np.ceil(np.linalg.norm(end[:3, 3] - start[:3, 3]) / step - 1e-9)))
    out = []
    for i in range(1, n + 1):
        T = end.copy()
        T[:3, 3] = start[:3, 3] + (end[:3, 3] - start[:3, 3]) * i / n
        out.append(T)
    return out


def turn_arc(start: np.ndarray, end: np.ndarray, center: np.ndarray, axis: np.ndarray = (0.0, 0.0, 1.0),
             step_deg: float = 5.0) -> list[np.ndarray]:
    """Waypoints from ``start`` to ``end`` turning about the line through ``center`` along ``axis``.

    A turn held in the hand must follow the arc: one joint-space motion between its ends can swing the
    hand far off it (measured: down to the table). Consecutive waypoints ``step_deg`` apart are joined by
    straight lines whose chord deviates from the arc by under 0.1 mm at 10 cm radius.
    """
    from common.geometry import rotation_about_line, yaw_deg_about

    rel = end @ np.linalg.inv(start)
    total = yaw_deg_about(axis, rel[:3, :3])
    n = max(1, int(np.ceil(abs(total) / step_deg)))
    c = np.array([center[0], center[1], 0.0])
    points = [rotation_about_line(axis, c, np.radians(total * i / n)) @ start for i in range(1, n)]
    return [*points, end]


def radial_offset_deg(grasp: Grasp, center: np.ndarray) -> float:
    """Signed angle (deg, counter-clockwise seen from above) from the line base → object to a grasp's
    horizontal approach direction; 0 for a straight-down approach.

    The arm reaches far-away low poses only roughly radially, so side approaches are tried last, and a
    turn is made in the direction that brings the hand back toward radial.
    """
    if "grasp" not in grasp.poses:
        return 180.0
    T = grasp.poses["grasp"].matrix()
    radial = np.array([center[0], center[1]])
    approach = np.array([T[0, 0], T[1, 0]])
    if np.linalg.norm(approach) < 1e-6:
        return 0.0
    cross = radial[0] * approach[1] - radial[1] * approach[0]
    return float(np.degrees(np.arctan2(cross, radial @ approach)))


def _at_height(T: np.ndarray, z: float) -> np.ndarray:
    out = T.copy()
    out[2, 3] = max(out[2, 3], z)
    return out


def _signed_offset(name: str) -> float:
    """The angular offset (deg) a pose name carries: ``grasp_minus45`` → -45, ``grasp`` → 0."""
    digits = "".join(ch for ch in name if ch.isdigit())
    return -float(digits or 0) if "minus" in name else float(digits or 0)


def _base_side_first(name: str) -> float:
    """Top-down grasps: the planner's offsets turn the hand about its grasp line, and a negative one leans
    the approach toward the arm's base (``services/grasp/poses.py``: z points away from the base, x' =
    cos(a) x - sin(a) z). Most negative first."""
    return _signed_offset(name)


def _offset_order(name: str) -> tuple[int, int]:
    """grasp first, then ±15, ±30, ... (plus before minus), as the planner intends."""
    if name == "grasp":
        return (0, 0)
    digits = "".join(ch for ch in name if ch.isdigit())
    return (int(digits or 0), 0 if "plus" in name else 1)


def object_box(center: np.ndarray, height: float, cloud_xyz: np.ndarray, margin: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(centre, extent) of an axis-aligned box around the object for collision checks."""
    xy = np.asarray(cloud_xyz)[:, :2]
    lo, hi = xy.min(axis=0) - margin, xy.max(axis=0) + margin
    c = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (height + margin) / 2])
    return c, np.array([hi[0] - lo[0], hi[1] - lo[1], height + margin])

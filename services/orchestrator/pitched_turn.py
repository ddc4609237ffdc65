"""The turn of a box only a pitched pick can hold: pick it pitched, carry it nearer the base, stand it upright
turned, set it down there. Geometry only (plain functions over poses, tested without a robot); the state
machine's side (where, which turn first, the record) is ``pitched_turn_step.py``.

Why: a slab thin along the line from the base and wider than the gripper's stroke the other way (a
generated box 5.4 x 15.8 x 15.3 cm at 0.60 m) is held only across its thin side, and the only pick of that
the arm reaches there is the top-down one pitched away from the base (``services/grasp/pitch.py``). Its
lay-down is no use (lying on its other edge it stands 16.4 cm, no lower), and no frontal or top-down turn
of it reaches at 0.60 m: the run ended "no executable grasp; limit: reach" at view 0. Once lifted the box
sits on the pads as the unpitched top-down grasp holds it, tilted by the pitch; a straight-down hand is what
sets it down upright, and the arm points straight down only nearer the base (at 0.40-0.425 m, not at
0.60 m). So the hand carries it there, turns back upright and about the vertical on the way (rotating
about its TCP, between the lifted pick and the upright pose above the spot), lowers it until it is
``RELEASE_GAP`` above the table, opens, and leaves upward leaning away from the base (``LEANS_DEG``).

Its turn: a quarter turn (the box's thin side then lies across the line from the base, where ordinary
grasps close across it) or the view's own turn; ``pitched_turn_step.py`` says which first and how each is
recorded. Either way the carry is one a relocated set-down records (``regrasp.relocation_shift``: the next
scan poses are placed around the spot).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from common.geometry import rotation_about_line
from common.messages import Grasp
from services.grasp.pitch import pitched
from services.orchestrator.config import TurnMotion
from services.orchestrator.lay_down import RELEASE_GAP, ROLL_HALF, TIP_CLEARANCE, lowest_point, whole_object
from services.orchestrator.planning import ChainMove, TurnPoses, carry_line

#: ``TurnPoses.direction`` of a quarter turn (times the sign of its angle): not one of the view's turns.
QUARTER_TURN = 3
#: Degrees of a quarter turn.
QUARTER_DEG = 90.0
#: Degrees the released hand leans away from the base on its way up, most first: a straight-down hand reaches
#: only 15 cm high at 0.40 m from the base (the arm's kinematics), too low to leave a 15 cm box straight up.
LEANS_DEG = (35.0, 20.0, 0.0)
#: Degrees between the waypoints of the hand's rotation back upright (straight lines between them).
STEP_DEG = 10.0
#: The grasp line of the unpitched pose must be this level (|z| of the pads' closing axis) to stand the
#: object upright on a straight-down hand.
LEVEL_TOL = 0.2


@dataclass
class PitchedTurnPoses(TurnPoses):
    """A pitched pick, lift, carry (``carry``: at the lift height), the hand's rotation upright and about the
    vertical (``upright``: waypoints, the last is ``turned_lifted``), set-down, straight-up retreat.
    ``carry_first``: carried pitched, then rotated on the spot; else rotated while carried."""

    carry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    upright: list[np.ndarray] = field(default_factory=list)
    leave: list[np.ndarray] = field(default_factory=list)  # the released hand's way up, leaning (last: retreat)
    turn_deg: float = 0.0
    lean_deg: float = 0.0

    def straight_moves(self, center: np.ndarray) -> list[ChainMove]:
        """Down to the pre-grasp, approach, lift, the carry and rotation waypoints, set down, retreat, up: all
        straight lines, checked in full before the hand sets off, as every chain is."""
        moves = [ChainMove("down to pre-grasp", self.pregrasp, "approach", contact=False),
                 ChainMove("approach", self.grasp, "approach"),
                 ChainMove("lift", self.lifted, "held")]
        moves += [ChainMove("turn", w, "held") for w in self.upright]
        moves.append(ChainMove("set down", self.turned, "held"))
        moves += [ChainMove("retreat", w, "released") for w in self.leave or [self.retreat]]
        moves.append(ChainMove("up", self.above_retreat, "released"))
        return moves


def hand_path(start: np.ndarray, end: np.ndarray, step_deg: float = STEP_DEG, step_m: float = 0.05
              ) -> list[np.ndarray]:
    """Waypoints from ``start`` to ``end`` (the last is ``end``): the rotation interpolated about the TCP and
    the TCP moved on the straight line between, at most ``step_deg`` and ``step_m`` apart."""
    R = Rotation.from_matrix(np.stack([start[:3, :3], end[:3, :3]]))
    angle = float(np.degrees(np.linalg.norm((R[1] * R[0].inv()).as_rotvec())))
    dist = float(np.linalg.norm(end[:3, 3] - start[:3, 3]))
    n = max(1, int(np.ceil(max(angle / step_deg, dist / step_m) - 1e-9)))
    slerp = Slerp([0.0, 1.0], R)
    out = []
    for i in range(1, n + 1):
        t = i / n
        T = np.eye(4)
        T[:3, :3] = slerp([t]).as_matrix()[0]
        T[:3, 3] = start[:3, 3] + t * (end[:3, 3] - start[:3, 3])
        out.append(T)
    out[-1] = end.copy()
    return out


def pitched_turn_sequences(grasp: Grasp, xyz: np.ndarray, center: np.ndarray, height: float,
                           motion: TurnMotion, shifts: list[np.ndarray],
                           angles_deg: tuple[float, ...] = (QUARTER_DEG, -QUARTER_DEG),
                           leans_deg: tuple[float, ...] = LEANS_DEG, view_turn_deg: float = 30.0
                           ) -> list[PitchedTurnPoses]:
    """For each pitched pose of ``grasp`` (``grasp_pitch*``, the pads as planned or swapped), each carry in
    ``shifts``, each turn in ``angles_deg`` and each lean of the way up (``view_turn_deg``: the session's turn,
    which a turn that far is recorded as, ``turn_direction``): the chain that picks it pitched and
    sets it down upright at the carried spot, turned that far about the vertical through its centre. Carried
    pitched first then turned upright on the spot, and both at once, in that order."""
    poses = {name: p.matrix() for name, p in grasp.poses.items()}
    if "grasp" not in poses:
        return []
    pts = whole_object(xyz, center)
    out: list[PitchedTurnPoses] = []
    for d in shifts:
        for name in sorted(n for n in poses if n.startswith("grasp") and pitched(n)):
            pre = poses.get("pre" + name)
            if pre is None:
                continue
            for flip, tag in ((np.eye(4), ""), (ROLL_HALF, "_rolled")):
                for angle in angles_deg:
                    for lean in leans_deg:
                        for carry_first in (True, False):
                            seq = _chain(poses[name] @ flip, pre @ flip, poses["grasp"] @ flip, name + tag, pts,
                                         np.asarray(center, float), height, np.asarray(d, float), motion,
                                         float(angle), float(lean), carry_first, view_turn_deg)
                            if seq is not None:
                                out.append(seq)
    return out


def turn_direction(angle_deg: float, view_turn_deg: float) -> int:
    """``TurnPoses.direction`` of a turn by ``angle_deg``: +-1 for the view's own turn (recorded as any turn),
    +-``QUARTER_TURN`` for a quarter turn."""
    sign = 1 if angle_deg > 0 else -1
    return sign if abs(abs(angle_deg) - abs(view_turn_deg)) < 1e-6 else sign * QUARTER_TURN


def leaned_away(T: np.ndarray, lean_deg: float) -> np.ndarray:
    """``T`` turned by ``lean_deg`` about its own grasp line (y) through its TCP, the approach leaning away
    from the arm's base: the open pads slide along the faces they held (those faces are across y)."""
    if not lean_deg:
        return T.copy()
    tcp = T[:3, 3]
    out_dir = np.array([tcp[0], tcp[1], 0.0]) / max(float(np.hypot(tcp[0], tcp[1])), 1e-9)
    best = None
    for sign in (1.0, -1.0):
        R = rotation_about_line(T[:3, 1], tcp, np.radians(sign * lean_deg)) @ T
        score = float(R[:3, 0] @ out_dir)
        if best is None or score > best[0]:
            best = (score, R)
    assert best is not None
    return best[1]


def _chain(g: np.ndarray, pre: np.ndarray, seated: np.ndarray, name: str, pts: np.ndarray, center: np.ndarray,
           height: float, d: np.ndarray, motion: TurnMotion, angle: float, lean: float,
           carry_first: bool, view_turn_deg: float) -> PitchedTurnPoses | None:
    """One chain (see ``pitched_turn_sequences``), or None when the seated grasp line is not level."""
    if abs(float(seated[2, 1])) > LEVEL_TOL:
        return None
    held = np.linalg.inv(seated)  # the object's standing pose in the hand, once seated
    spot = np.array([center[0] + d[0], center[1] + d[1], 0.0])
    moved = seated.copy()
    moved[:3, 3] += d
    final = rotation_about_line(np.array([0.0, 0.0, 1.0]), spot, np.radians(angle)) @ moved  # upright, turned

    def path(lift: float) -> list[np.ndarray]:
        up = np.array([0.0, 0.0, lift])
        a = g.copy()
        a[:3, 3] += up
        b = final.copy()
        b[:3, 3] += up + np.array([0.0, 0.0, RELEASE_GAP])
        if not carry_first:
            return hand_path(a, b)
        carried = a.copy()
        carried[:3, 3] += d
        line = carry_line(a, carried) if float(np.linalg.norm(d)) > 1e-6 else []
        return [*line, *hand_path(carried, b)]

    lift = motion.lift
    low = min(lowest_point(T, held, pts) for T in path(lift))
    if low < TIP_CLEARANCE:  # the tilted object would sweep the table: lift higher first
        lift += TIP_CLEARANCE - low
    upright = path(lift)
    lifted = g.copy()
    lifted[2, 3] += lift
    turned = final.copy()
    turned[2, 3] += RELEASE_GAP
    top = float(height) + RELEASE_GAP
    back = max(float(np.linalg.norm(pre[:3, 3] - g[:3, 3])), 0.02)
    retreat = leaned_away(turned, lean)  # up, leaning away from the base as it rises (``LEANS_DEG``)
    retreat[:3, 3] -= back * turned[:3, 0]
    leave = hand_path(turned, retreat)
    above = retreat.copy()
    above[2, 3] = max(above[2, 3], top + motion.clearance)
    above_pre = pre.copy()
    above_pre[2, 3] = max(above_pre[2, 3], float(pts[:, 2].max()) + motion.clearance)
    carried = float(np.linalg.norm(d)) >= 1e-6
    carry_from = upright[-1].copy()  # the set-down pose moved back by the carry: ``regrasp.relocation_shift`` reads d
    carry_from[:3, 3] -= d
    tag = f"_turn{angle:+g}" + ("" if carry_first else "_carried") + (f"_lean{lean:g}" if lean else "") + \
        (f"@{d[0]:+.2f},{d[1]:+.2f}" if carried else "")
    return PitchedTurnPoses(name=f"{name}{tag}", above_pregrasp=above_pre, pregrasp=pre, grasp=g.copy(),
                            lifted=lifted, turned_lifted=upright[-1], turned=turned, retreat=retreat,
                            above_retreat=above, direction=turn_direction(angle, view_turn_deg),
                            carry_from=carry_from if carried else None,
                            carry=d.copy(), upright=upright, leave=leave, turn_deg=angle, lean_deg=lean)


"""Laying a tall object on its side: a pick-and-place that tips it 90 degrees about the grasp line, for an
object no grasp can turn standing. Geometry here is plain functions over poses, tested without a robot.

Why: a tall box (21-24 cm, 6 cm thick) standing at the workspace centre offers grasps only across its
thickness; every pick-turn-place of them left the arm's reach (measured in whole MuJoCo acquisitions: 192
refusals at view 0, at every spot a relocation or a reposition tried) and the run ended "no executable
grasp; limit: reach". Lying on its side the same object is low and long, and a top-down grasp across it
turns it like any lying bottle (``recovery.py``). The arm can make that move: grip the standing object
from the side, lift it, rotate the hand 90 degrees about the grasp line (the pads' contact line, so the
object swings about the line it is held on, the hand ending above it pointing down) and set it down.
The PAPRAS wrist cannot point straight down at the object's 0.60 m (``planning.turn_sequences``), but it can
on the near ring of ``RelocationConfig`` (0.40 m from the base): the object is carried there, lifted, before
it is tipped (``carry_shifts``: where it stands first, then the ring's spots, shortest carry first).

What follows is a restart of the views where it now lies: the views of the standing object are set aside
(kept on disk, as after a topple), view 0 is scanned again lying, the journal records the move
(``laid_down``) and every later plan treats the object as lying (top-down and frontal grasps alike).

Not modelled: the swing of the held object about the grasp line (the grasp closest to the estimated centre
of mass is tried first, where that torque is least; the twin keeps the in-hand pose during a carry).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from common.geometry import rotation_about_line
from common.messages import Grasp
from services.grasp.pitch import pitched
from services.orchestrator.config import RelocationConfig, TurnMotion
from services.orchestrator.planning import ChainMove, TurnPoses, carry_line
from services.orchestrator.regrasp import relocation_shifts

#: ``TurnPoses.direction`` of a pick-and-place that lays the object on its side.
LAY_DOWN = 2
#: An object at least this many times taller than its thinnest horizontal extent is laid down only when
#: nothing turns it standing; a squatter one gains little lying and rolls more.
TALL_RATIO = 1.4
#: m the held object's lowest point stays above the table while it is tipped.
TIP_CLEARANCE = 0.02
#: m above the table the object is released at (it drops that far; the twin and a real arm both stop
#: on contact if the hidden side reaches lower than estimated).
RELEASE_GAP = 0.004
#: The hand turned half a turn about its approach: the same parallel grasp with the pads swapped.
ROLL_HALF = np.diag([1.0, -1.0, -1.0, 1.0])
#: Yaws (deg) of the level approach a pitched pick's lay-down ends in, from the line from the base (``_leaned``).
LEVEL_YAWS_DEG = (0.0, 25.0, -25.0)
#: Degrees between the waypoints of the tip arc (straight lines between them, like the turn's arc).
TIP_STEP_DEG = 10.0


@dataclass
class LayDownPoses(TurnPoses):
    """A pick, lift, carry (``carry``: shift at the lift height), tip (90 degrees about the grasp line
    ``axis`` through ``pivot`` at the carried lift height), set-down and retreat. ``turned_lifted`` is the
    tipped hand before it is lowered; ``turned`` the release pose. ``lying_center``, ``lying_height`` and
    ``lying_corners``: where the object is expected to rest, how tall it is then, its footprint's box."""

    carry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tip_deg: float = 90.0
    lying_center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    lying_height: float = 0.0
    lying_corners: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))  # footprint's lowest, highest
    roll_deg: float = 0.0  # a turn about the hand's approach through ``pivot`` before the tip (a pitched pick)
    roll_last: bool = False  # the roll after the tip instead (about the tipped approach)
    #: the tip as turns (axis, degrees, in joint-space chords) about lines through ``pivot``, in order, replacing
    #: the single tip about ``axis`` when given (``_tipped``: a turn about the vertical, then the tip)
    arcs: list[tuple[np.ndarray, float, bool]] = field(default_factory=list)

    def straight_moves(self, center: np.ndarray) -> list[ChainMove]:
        """Down to the pre-grasp, approach, lift, carry, tip (in ``TIP_STEP_DEG`` chords), set down,
        retreat, up: all straight lines, checked in full before the hand sets off, as every chain is."""
        moves = [ChainMove("down to pre-grasp", self.pregrasp, "approach", contact=False),
                 ChainMove("approach", self.grasp, "approach"),
                 ChainMove("lift", self.lifted, "held")]
        carried = self.lifted.copy()
        carried[:3, 3] += self.carry
        if float(np.linalg.norm(self.carry)) > 1e-6:
            moves += [ChainMove("carry", w, "held") for w in carry_line(self.lifted, carried)]
        for axis, deg, joint in self.arcs:
            arc = tip_arc(carried, axis, self.pivot, deg)
            moves += [ChainMove("lay down", w, "held", joint=joint) for w in arc]
            carried = arc[-1]
        if self.arcs:
            return moves + self._released()
        if self.roll_deg and not self.roll_last:
            rolled = tip_arc(carried, carried[:3, 0], self.pivot, self.roll_deg)
            moves += [ChainMove("lay down", w, "held") for w in rolled]
            carried = rolled[-1]
        tipped = tip_arc(carried, self.axis, self.pivot, self.tip_deg)
        moves += [ChainMove("lay down", w, "held") for w in tipped]
        if self.roll_deg and self.roll_last:
            moves += [ChainMove("lay down", w, "held")
                      for w in tip_arc(tipped[-1], tipped[-1][:3, 0], self.pivot, self.roll_deg)]
        return moves + self._released()

    def _released(self) -> list[ChainMove]:
        return [ChainMove("set down", self.turned, "held"), ChainMove("retreat", self.retreat, "released"),
                ChainMove("up", self.above_retreat, "released")]


def tip_arc(start: np.ndarray, axis: np.ndarray, pivot: np.ndarray, angle_deg: float,
            step_deg: float = TIP_STEP_DEG) -> list[np.ndarray]:
    """Waypoints rotating ``start`` by ``angle_deg`` about the line through ``pivot`` along ``axis``; the last
    is the whole rotation. A held object must follow the arc (a joint motion between the ends swings it)."""
    n = max(1, int(np.ceil(abs(angle_deg) / step_deg)))
    return [rotation_about_line(axis, pivot, np.radians(angle_deg * i / n)) @ start for i in range(1, n + 1)]



def lowest_point(hand: np.ndarray, held: np.ndarray, pts: np.ndarray) -> float:
    """Height of the held object's lowest point with the hand at ``hand``; ``held`` is the object's pose in the
    hand, ``pts`` its points in its own frame."""
    M = hand @ held
    return float((pts @ M[:3, :3].T + M[:3, 3])[:, 2].min())

def stands_tall(xyz: np.ndarray, height: float, ratio: float = TALL_RATIO) -> bool:
    """Whether the standing object is markedly taller than its thinnest horizontal extent (the height it
    would have lying on that side)."""
    pts = np.asarray(xyz, float)
    if len(pts) < 3 or height <= 0:
        return False
    xy = pts[:, :2] - pts[:, :2].mean(axis=0)
    _, vecs = np.linalg.eigh(xy.T @ xy)
    thin = float(np.ptp(xy @ vecs[:, 0]))
    return thin > 0 and height >= ratio * thin


def whole_object(xyz: np.ndarray, center: np.ndarray) -> np.ndarray:
    """The cloud of one view and its mirror through the vertical line at ``center``: the wrist camera sees the
    arm's side of the object; its far side is taken as symmetric, so the far face's reach is estimated."""
    pts = np.asarray(xyz, float)
    mirrored = pts.copy()
    mirrored[:, :2] = 2 * np.asarray(center, float)[:2] - pts[:, :2]
    return np.vstack([pts, mirrored])


def carry_shifts(center: np.ndarray, config: RelocationConfig) -> list[np.ndarray]:
    """Where the object is tipped: where it stands, then the relocation spots (the near ring, where the
    wrist points straight down), shortest carry first."""
    return [np.zeros(3), *relocation_shifts(center, config)]


def lay_down_sequences(grasp: Grasp, xyz: np.ndarray, center: np.ndarray, height: float, motion: TurnMotion,
                       shifts: list[np.ndarray]) -> list[LayDownPoses]:
    """For each of ``grasp``'s angular offsets with a horizontal grasp line and each carry in ``shifts``, the
    chain that tips the object 90 degrees about the grasp line so that the hand ends above it (the approach
    pointing down), then lowers it until its lowest point is ``RELEASE_GAP`` above the table. A pitched pick
    (``grasp_pitch*``) lays it down the other way (``_leaned``), centred where the carry takes it."""
    poses = {name: p.matrix() for name, p in grasp.poses.items()}
    pts = whole_object(xyz, center)
    out: list[LayDownPoses] = []
    for d in shifts:
        d = np.asarray(d, float)
        for name in (n for n in poses if n.startswith("grasp")):
            suffix = name[len("grasp"):]
            pre = poses.get("pregrasp" + suffix)
            if pre is None:
                continue
            for flip, tag in ((np.eye(4), ""), (ROLL_HALF, "_rolled")):  # the pads swapped: another wrist branch
                if pitched(name):  # held, once seated on the pads, as the unpitched grasp holds it
                    args = (poses[name] @ flip, pre @ flip, poses["grasp"] @ flip, name + tag, pts)
                    for yaw in LEVEL_YAWS_DEG:
                        for last in (True, False):
                            seq = _leaned(*args, d, motion, last, yaw)
                            if seq is not None:  # it lies beyond the hand: carried so it lies centred on its spot
                                shift = np.array([*(center[:2] + d[:2] - seq.lying_center[:2]), 0.0])
                                seq = _leaned(*args, d + shift, motion, last, yaw)
                            if seq is not None:
                                out.append(seq)
                    continue
                g = poses[name] @ flip
                for radial in (False, True):
                    seq = _tipped(grasp, g, pre @ flip, name + tag, pts, d, motion, radial)
                    if seq is not None:
                        out.append(seq)
    return out


def _leaned(g: np.ndarray, pre: np.ndarray, seated: np.ndarray, name: str, pts: np.ndarray, d: np.ndarray,
            motion: TurnMotion, roll_last: bool = False, yaw_deg: float = 0.0) -> LayDownPoses | None:
    """The lay-down of a pitched top-down pick ``g`` (``services/grasp/pitch.py``) carried by ``d``: the hand
    rolls 90 degrees about its approach (the grasp line turns across the line from the base), then pitches
    about the grasp line until its approach points horizontally away from the base (the object's top toward
    the base, its thin side across the line from the base, where a top-down grasp closes the way the arm
    reaches), both about its TCP: the approach keeps leaning away from the base, the lean the arm reaches,
    all the way (one rotation straight to the end needed a wrist flip half-way, measured). Then it lowers the
    object until its lowest point is ``RELEASE_GAP`` above the table and leaves straight up, the pads sliding
    off the object's sides. ``seated`` is the unpitched grasp: once lifted the object sits on the pads as that
    grasp holds it. ``roll_last``: tip first (about the hand's z, until the approach is level), then roll
    (about the level approach); which of the two orders keeps the wrist on one branch depends on the pick
    (measured on a registered view: only roll-last did). ``yaw_deg``: the level approach turned that far
    from the line from the base (straight along it, the wrist can end at its singularity, joints 4 and 6 in
    line: measured on a 15 cm box, every order needed a joint jump). None when the grasp line is not level
    when seated."""
    if abs(float(seated[2, 1])) > 0.2:
        return None
    held = np.linalg.inv(seated)  # the object's standing pose in the hand, once seated
    tcp = g[:3, 3] + d
    out = tcp[:2] / max(float(np.linalg.norm(tcp[:2])), 1e-9)
    c, s_ = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    x = np.array([c * out[0] - s_ * out[1], s_ * out[0] + c * out[1], 0.0])
    carried0 = g.copy()
    carried0[:3, 3] += d
    turn = _tip_then_roll(carried0, tcp, x) if roll_last else _roll_then_tip(carried0, tcp, x)
    if turn is None:
        return None
    arc, axis, angle, roll = turn

    lift = max(motion.lift, TIP_CLEARANCE - min(lowest_point(T, held, pts) for T in arc))
    up = np.array([0.0, 0.0, lift])
    lifted = g.copy()
    lifted[2, 3] += lift
    tipped_lifted = arc[-1].copy()
    tipped_lifted[:3, 3] += up
    drop = lowest_point(tipped_lifted, held, pts) - RELEASE_GAP
    lowered = tipped_lifted.copy()
    lowered[2, 3] -= drop
    M = lowered @ held
    rest = pts @ M[:3, :3].T + M[:3, 3]
    top = float(rest[:, 2].max())
    retreat = lowered.copy()  # straight up: the open pads slide off the object's sides
    retreat[2, 3] = max(retreat[2, 3], top + motion.clearance)
    above = retreat.copy()
    above_pre = pre.copy()
    above_pre[2, 3] = max(above_pre[2, 3], float(pts[:, 2].max()) + motion.clearance)
    lo, hi = rest[:, :2].min(axis=0), rest[:, :2].max(axis=0)
    tag = ("_roll_last" if roll_last else "") + (f"_yaw{yaw_deg:+g}" if yaw_deg else "")
    tag += "" if float(np.linalg.norm(d)) < 1e-6 else f"@{d[0]:+.2f},{d[1]:+.2f}"
    return LayDownPoses(name=f"{name}_lay_down{tag}", above_pregrasp=above_pre, pregrasp=pre, grasp=g.copy(),
                        lifted=lifted, turned_lifted=tipped_lifted, turned=lowered, retreat=retreat,
                        above_retreat=above, direction=LAY_DOWN, carry=d.copy(), axis=axis,
                        pivot=tcp + up, tip_deg=angle, roll_deg=roll, roll_last=roll_last,
                        lying_center=np.array([*(0.5 * (lo + hi)), 0.0]),
                        lying_height=top, lying_corners=np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0]]))


#: (hand waypoints from the carried pick to the level approach, tip axis, tip angle deg, roll angle deg)
LeanTurn = tuple[list[np.ndarray], np.ndarray, float, float]


def _tip_then_roll(carried: np.ndarray, tcp: np.ndarray, x: np.ndarray) -> LeanTurn:
    """About the hand's z until the approach is ``x`` (the shortest way), then about the level approach by the
    roll that levels the pads (the nearer of the two), both about the TCP."""
    v = np.cross(carried[:3, 0], x)
    axis = v / max(float(np.linalg.norm(v)), 1e-12)
    angle = float(np.degrees(np.arctan2(np.linalg.norm(v), float(carried[:3, 0] @ x))))
    level = rotation_about_line(axis, tcp, np.radians(angle)) @ carried
    # about x by r: y' = cos(r) y + sin(r) z, level when cos(r) y_z + sin(r) z_z = 0 (the nearer of two)
    roll = float(np.degrees(np.arctan2(-level[2, 1], level[2, 2])))
    roll = roll - 180.0 * np.sign(roll) if abs(roll) > 90.0 else roll
    tipped = tip_arc(carried, axis, tcp, angle)
    return [carried, *tipped, *tip_arc(tipped[-1], tipped[-1][:3, 0], tcp, roll)], axis, angle, roll


def _roll_then_tip(carried: np.ndarray, tcp: np.ndarray, x: np.ndarray) -> LeanTurn | None:
    """A quarter roll about the hand's approach (the sign needing the smaller tip after it), then one
    rotation to the level approach ``x`` with the pads level, both about the TCP; None when nothing is left
    to turn."""
    best: tuple[float, np.ndarray] | None = None
    for r in (90.0, -90.0):
        rolled = rotation_about_line(carried[:3, 0], tcp, np.radians(r)) @ carried
        for z in (np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])):
            final = np.column_stack([x, np.cross(z, x), z])
            rotvec = Rotation.from_matrix(final @ rolled[:3, :3].T).as_rotvec()
            if best is None or np.linalg.norm(rotvec) < np.linalg.norm(best[1]):
                best = (r, rotvec)
    assert best is not None
    roll, rotvec = best
    angle = float(np.degrees(np.linalg.norm(rotvec)))
    if angle < 1e-6:
        return None
    axis = rotvec / np.linalg.norm(rotvec)
    rolled_arc = tip_arc(carried, carried[:3, 0], tcp, roll)
    return [carried, *rolled_arc, *tip_arc(rolled_arc[-1], axis, tcp, angle)], axis, angle, roll


def _tipped(grasp: Grasp, g: np.ndarray, pre: np.ndarray, name: str, pts: np.ndarray, d: np.ndarray,
            motion: TurnMotion, radial: bool = False) -> LayDownPoses | None:
    """One lay-down chain of grasp pose ``g`` carried by ``d``, or None when its grasp line is not horizontal
    or no tip leaves the hand above the object.

    ``radial``: the held object is first turned about the vertical until the approach points along the line
    from the base through the hand, then tipped about the level line across it, in joint-space chords. The
    straight tip about the grasp line passes the wrist's singularity (joint 5 at 0) where the hand, level at
    the pick, ends pointing down: a straight line's dense IK turns joints 4 and 6 half a turn there, past their
    limits, and no split of the tip round the forearm reaches the end (measured on a 24 cm box carried to the
    near ring: the end pose, pointing down, has one wrist branch within the limits, the other side of joint 5
    from the pick's). In the arm's vertical plane the joint move crosses it with joint 5 alone."""
    if abs(float(g[2, 1])) > 0.2:  # the tip must turn the object's vertical axis into a horizontal one
        return None
    line = np.asarray(g[:3, 1], float)
    m = np.asarray(grasp.contacts, float).mean(axis=0)  # on the grasp line
    rel = pts - m
    radius = float(np.max(np.linalg.norm(rel - np.outer(rel @ line, line), axis=1)))
    lift = max(motion.lift, radius + TIP_CLEARANCE - float(m[2]))
    yaw_deg = 0.0
    tip_line = line
    if radial:
        out = g[:2, 3] + d[:2]  # where the hand will be when it tips: the line from the base through it
        yaw_deg = float(np.degrees(np.arctan2(out[1], out[0]) - np.arctan2(g[1, 0], g[0, 0])))
        yaw_deg = (yaw_deg + 180.0) % 360.0 - 180.0
        tip_line = np.array([-out[1], out[0], 0.0]) / max(float(np.linalg.norm(out)), 1e-9)
    Y = rotation_about_line(np.array([0.0, 0.0, 1.0]), m, np.radians(yaw_deg))

    def whole(sign: float) -> np.ndarray:
        return rotation_about_line(tip_line, m, np.radians(sign * 90.0)) @ Y

    sign = max((1.0, -1.0), key=lambda sg: -float((whole(sg)[:3, :3] @ g[:3, 0])[2]))
    R = whole(sign)
    if -float((R[:3, :3] @ g[:3, 0])[2]) < 0.7:  # the object would end above the hand
        return None
    moved = pts @ R[:3, :3].T + R[:3, 3] + d  # where the object is when tipped on the table, carried by d
    drop = float(moved[:, 2].min()) - RELEASE_GAP
    lowered = R @ g
    lowered[:3, 3] += d - np.array([0.0, 0.0, drop])
    lifted = g.copy()
    lifted[2, 3] += lift
    tipped_lifted = R @ g
    tipped_lifted[:3, 3] += d + np.array([0.0, 0.0, lift])
    back = float(np.linalg.norm(pre[:3, 3] - g[:3, 3]))
    retreat = lowered.copy()
    retreat[:3, 3] -= back * lowered[:3, 0]
    rest = moved - np.array([0.0, 0.0, drop + RELEASE_GAP])
    above = retreat.copy()  # clear of the object as it now lies: the next moves are joint motions
    if not radial:  # pointing down on the near ring the hand reaches no higher than the retreat (about 0.14 m);
        # backed off along its approach as far as the pre-grasp stood, its open pads are clear of the top already
        above[2, 3] = max(above[2, 3], float(rest[:, 2].max()) + motion.clearance)
    above_pre = pre.copy()  # clear of the standing object
    above_pre[2, 3] = max(above_pre[2, 3], float(pts[:, 2].max()) + motion.clearance)
    lo, hi = rest[:, :2].min(axis=0), rest[:, :2].max(axis=0)
    arcs = [(np.array([0.0, 0.0, 1.0]), yaw_deg, False), (tip_line, 90.0 * sign, True)] if radial else []
    tag = ("_radial" if radial else "") + ("" if float(np.linalg.norm(d)) < 1e-6 else f"@{d[0]:+.2f},{d[1]:+.2f}")
    return LayDownPoses(name=f"{name}_lay_down{tag}", above_pregrasp=above_pre, pregrasp=pre, grasp=g.copy(),
                        lifted=lifted, turned_lifted=tipped_lifted, turned=lowered, retreat=retreat,
                        above_retreat=above, direction=LAY_DOWN, carry=d.copy(), axis=tip_line.copy(),
                        pivot=m + d + np.array([0.0, 0.0, lift]), tip_deg=90.0 * sign, arcs=arcs,
                        lying_center=np.array([*(0.5 * (lo + hi)), 0.0]), lying_height=float(rest[:, 2].max()),
                        lying_corners=np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0]]))


def grasps_for_lay_down(grasps: list[Grasp], height: float) -> list[int]:
    """Indices of ``grasps`` in the order to try them for a lay-down: frontal ones first (their hand ends
    above the object), then the grasps whose line passes nearest the object's mid-height (the least swing
    about the grasp line while it tips), then the planner's order."""
    def key(i: int) -> tuple[bool, float, int]:
        z = float(np.asarray(grasps[i].contacts, float)[:, 2].mean())
        return (grasps[i].kind != "frontal", round(abs(z - 0.5 * height), 2), i)

    return sorted(range(len(grasps)), key=key)


def as_recorded(seq: LayDownPoses) -> dict:
    """The journal's ``laid_down`` entry for a chain about to be executed: what the record at the release
    needs (where the object will lie and how tall) and what the report says."""
    return {"state": "planned", "pose": seq.name, "tip_deg": round(float(seq.tip_deg), 1),
            "carry": np.round(seq.carry, 4).tolist(), "center": np.round(seq.lying_center, 4).tolist(),
            "height": round(float(seq.lying_height), 4)}

"""Turning an object the arm cannot pick by pushing it round: the poses of one push.

Why: from the arm's base the wrist reaches an object at the working distance (0.6 m) only roughly
radially: a frontal approach within about 50 degrees of the line from the base, and top-down only nearer
than about 0.45 m. A box whose one graspable side (the other is wider than the gripper's 10.6 cm stroke)
lies along that line offers its faces only to a side or top-down approach, so no pick, turn, reposition
or lay-down reaches it. Turned some 45 degrees on the table, the same box is picked frontally.

How: the closed hand stands low in front of the face that looks towards the base, at one end of it, and
its pad tips drive that end round an arc about the footprint's centre (straight chords, the hand's
orientation fixed). The box turns and slides ahead of the pads; in the MuJoCo twin a 90-degree arc turns
a 9.9 x 14.3 cm box about 50 degrees and moves it 4-7 cm outwards (measured). Pushing low (the hand 4 cm
above the table, at most half the object's height; lower, the wrist meets the table) turns a tall box
without tipping it.
What the push achieved is not assumed: it is measured (``measured_turn_deg``) on the view scanned where the
object then stands, or, where it cannot be, the views restart from a fresh scan (``push_step.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.footprint import min_area_rectangle
from services.grasp.config import GripperConfig

#: Degrees the pad tips travel round the footprint's centre (the box turns about half of it).
ARC_DEG = 90.0
#: Degrees of one straight chord of the arc.
CHORD_DEG = 7.5
#: Fraction of the face's half length from its middle where the pads push (near its end: the longest lever).
END_FRACTION = 0.85
#: m the pad tips start short of the face (close: low frontal poses nearer the base run into joint limits).
START_GAP = 0.012
#: m the hand backs off along its approach after the arc, before rising.
BACK_OFF = 0.05
#: A face looks towards the base when its outward normal is this far (cosine) against the line from the base.
FACING_COS = 0.35
#: m above the table the hand pushes at: low, so a tall box turns, not tips (lower, the wrist meets the table).
PUSH_HEIGHT = 0.04
#: Degrees the hand is pitched down for the pushes offered after the level ones. Near the base the level hand's
#: low poses are out of reach (PAPRAS kinematics: none at 0.28-0.40 m from the base, 4-6 cm up); pitched 30
#: degrees, every one from 0.28 m out is reached. The pad tips push at ``PUSH_HEIGHT`` all the same.
PUSH_PITCHES_DEG = (0.0, 30.0)


#: A footprint whose long side is under this many times its short side has no long side to measure a turn by.
MIN_ASPECT = 1.15
#: Degrees a push must have turned the box by, at least and at most, for the measure to be believed: less is a
#: push that slid the box without turning it, more than the pads' whole arc is a look at the wrong object.
MIN_MEASURED_DEG, MAX_MEASURED_DEG = 5.0, ARC_DEG + 15.0


@dataclass(frozen=True)
class PushPoses:
    """One push, as gripper poses in ``base``: over the start (clear of the object's top), the start (low,
    short of the face), the chords' ends round the arc, and the way back out (back off, then up)."""

    name: str
    above: np.ndarray
    start: np.ndarray
    arc: list[np.ndarray]
    retreat: list[np.ndarray]
    sense: int  # +1: the box is driven counter-clockwise seen from above, -1 clockwise
    expected_center: np.ndarray  # where the footprint's centre is expected afterwards (scan poses aim there)


def _hand(approach: np.ndarray, position: np.ndarray, pitch_deg: float = 0.0) -> np.ndarray:
    """A gripper pose approaching along ``approach`` (horizontal), pitched ``pitch_deg`` down about its y, z up-ish."""
    h = np.array([approach[0], approach[1], 0.0])
    h /= np.linalg.norm(h)
    up = np.array([0.0, 0.0, 1.0])
    a = np.radians(pitch_deg)
    x = np.cos(a) * h - np.sin(a) * up
    z = np.sin(a) * h + np.cos(a) * up
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, position
    return T


def _rotate(v: np.ndarray, deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([np.cos(a) * v[0] - np.sin(a) * v[1], np.sin(a) * v[0] + np.cos(a) * v[1]])


def push_sequences(xyz: np.ndarray, height: float, clearance: float, arc_deg: float = ARC_DEG,
                   gripper: GripperConfig | None = None, sense: int | None = None) -> list[PushPoses]:
    """The pushes of the object whose view cloud is ``xyz`` (``base``, standing ``height`` tall): one at each
    end of each face that looks towards the base (one face when the box stands square to the line from the
    base, two when it stands turned). Those turning it the way ``sense`` says first (a second push goes on
    turning it the way the first did), then the ones whose arc stays nearer the base."""
    pts = np.asarray(xyz, float)
    if len(pts) < 10:
        return []
    rect = min_area_rectangle(pts[:, :2])
    if not np.all(rect[2] > 0):
        return []
    g = gripper or GripperConfig()
    out: list[PushPoses] = []
    for pitch in PUSH_PITCHES_DEG:
        level = _pushes(rect, height, clearance, arc_deg, g, pitch)
        level.sort(key=lambda p: (sense is not None and p.sense != sense, float(np.linalg.norm(p.arc[-1][:2, 3]))))
        out += level
    return out


def _pushes(rect: tuple[np.ndarray, np.ndarray, np.ndarray], height: float, clearance: float, arc_deg: float,
            g: GripperConfig, pitch_deg: float) -> list[PushPoses]:
    """The pushes of ``push_sequences`` round the footprint's rectangle ``rect`` (centre, axes, sides) with the hand
    pitched ``pitch_deg`` down (the pad tips at the same height and the same point of the face)."""
    centre, axes, sides = rect
    a = np.radians(pitch_deg)
    tip, drop = 0.5 * g.pad_length * np.cos(a), 0.5 * g.pad_length * np.sin(a)
    # the hand approaches along the line from the base (where the wrist reaches farthest), not square to a face
    # turned away from it
    approach = centre / max(float(np.linalg.norm(centre)), 1e-9)
    z = min(PUSH_HEIGHT, 0.5 * height) + drop  # the TCP above the pad tips
    faces = [(s * axes[:, i], sides[i] / 2, axes[:, 1 - i], sides[1 - i] / 2) for i in (0, 1) for s in (1.0, -1.0)]
    facing = sorted((f for f in faces if float(f[0] @ approach) < -FACING_COS), key=lambda f: float(f[0] @ approach))
    out: list[PushPoses] = []
    for fi, (normal, depth, tangent, half) in enumerate(facing):
        # back along the approach until the pads' front edge (both pads side by side) is ``START_GAP`` out of the
        # face's plane, which puts it outside the box: a face turned from square meets a side corner first
        square = float(-normal @ approach)
        lateral = abs(float(normal @ np.array([-approach[1], approach[0]])))
        gap = (START_GAP + g.pad_thickness * lateral) / square
        for end in (1.0, -1.0):
            lever = normal * depth + tangent * end * END_FRACTION * half  # contact point from the centre
            # the sense of rotation a push along the approach at that point gives
            turn = 1 if float(lever[0] * approach[1] - lever[1] * approach[0]) > 0 else -1
            steps = max(1, int(np.ceil(arc_deg / CHORD_DEG)))
            contacts = [centre + _rotate(lever, turn * arc_deg * i / steps) for i in range(steps + 1)]
            arc = [_hand(approach, [*(p - approach * tip), z], pitch_deg) for p in contacts]
            start = _hand(approach, [*(contacts[0] - approach * (tip + gap)), z], pitch_deg)
            above = start.copy()
            above[2, 3] = height + clearance
            back = arc[-1].copy()
            back[:3, 3] -= back[:3, 0] * BACK_OFF
            up = back.copy()
            up[2, 3] = height + clearance
            moved = 0.5 * (contacts[-1] - contacts[0])  # the box follows the pads about half way (measured)
            name = f"push_face{fi}_{'left' if end > 0 else 'right'}_end" + (f"_pitch{pitch_deg:g}" if pitch_deg else "")
            out.append(PushPoses(name=name, above=above,
                                 start=start, arc=arc, retreat=[back, up], sense=turn,
                                 expected_center=np.array([*(centre + moved), 0.0])))
    return out


def long_side_deg(xy: np.ndarray) -> float | None:
    """Direction (deg, mod 180, about the table normal) of the long side of a footprint's smallest rectangle;
    None when the footprint is too near square (``MIN_ASPECT``) for its long side to say which way it lies."""
    pts = np.asarray(xy, float)
    if len(pts) < 10:
        return None
    _, axes, sides = min_area_rectangle(pts[:, :2])
    i = int(np.argmax(sides))
    if sides[1 - i] <= 0 or sides[i] < MIN_ASPECT * sides[1 - i]:
        return None
    return float(np.degrees(np.arctan2(axes[1, i], axes[0, i]))) % 180.0


def measured_turn_deg(before_deg: float, after_deg: float, sense: int) -> float | None:
    """The turn (deg, counter-clockwise seen from above positive) a push of ``sense`` gave an object whose
    footprint's long side lay at ``before_deg`` and lies at ``after_deg`` (``long_side_deg``); None when it is
    not a turn a push gives (``MIN_MEASURED_DEG`` to ``MAX_MEASURED_DEG``).

    Why a measure and not the arc: the box slides as it turns, so a 90-degree arc turned the 9.9 x 14.3 cm box
    35 to 70 degrees in the twin. The long side is a direction mod 180, and a push turns the box less than
    that one way: the sense picks the one answer."""
    turn = (after_deg - before_deg) % 180.0 if sense > 0 else -((before_deg - after_deg) % 180.0)
    return turn if MIN_MEASURED_DEG <= abs(turn) <= MAX_MEASURED_DEG else None

"""Regrasp strategies: what the state machine tries when no pick-turn-place is executable where the object
stands. Plain functions over poses, so each is tested without a robot.

Why they are needed: a thin box standing on edge (the HOPE cream cheese, 10.4 x 2.4 cm, 5.3 cm tall) has
antipodal grasps only across its 2.4 cm thickness, which ties the hand's yaw to the box's (``yaw_tied``).
Measured with the real kinematics and grasp planner (synthetic upright box, +30 and -30 deg turns, every
30 deg of yaw): at 0.60 m on the base's x axis a turn is executable from 4 yaws of 12; at 0.45 m the yaws
around "long side across the line from the base" (60-90 deg, 240-270 deg) fail at every azimuth tried
(0, +-30 deg); at 0.38-0.42 m a top-down turn is executable from **every** yaw, both ways.

So the strategy is a **relocated set-down**: the object is turned by the same commanded 30 deg and set
down at another spot (``relocation_shifts``: 0.40 m from the base at azimuths 0, +-30 deg, shortest carry
first), then scanned there. The dynamic registration stacks each view on its own centre
(``registration/dynamic/preprocess.prerotation``), so a moved object registers as a turned one.
- any object: relocated chains are tried when a direct chain's pick was reachable but its turn or
  set-down was not (the dry run failed at ``RELOCATABLE_STEPS``);
- a yaw-tied object farther than the near ring: relocated chains first (it is brought in on its first
  turn), with a two-step look-ahead (``grasp_after``: the same grasp where the set-down leaves the
  object must be turnable again).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from common.messages import Grasp, Pose
from services.orchestrator.config import RelocationConfig
from services.orchestrator.planning import TurnPoses


def relocation_shifts(center: np.ndarray, config: RelocationConfig) -> list[np.ndarray]:
    """In-plane shifts (x, y, 0) from the object's centre to the candidate set-down spots, shortest carry
    first (a spot on the object's own line nearer the base is usually that). Empty when disabled."""
    if not config.enabled:
        return []
    c = np.asarray(center, float)[:2]
    r = float(np.hypot(*c))
    radii = {config.near_radius} | ({round(r, 3)} if config.near_radius < r <= config.max_radius else set())
    out: list[np.ndarray] = []
    for rr in sorted(radii):
        for a in config.azimuths_deg:
            target = rr * np.array([np.cos(np.radians(a)), np.sin(np.radians(a))])
            shift = np.array([*(target - c), 0.0])
            if np.linalg.norm(shift) >= config.min_shift and not any(np.allclose(shift, o) for o in out):
                out.append(shift)
    return sorted(out, key=lambda d: float(np.linalg.norm(d)))


def relocated(seq: TurnPoses, shift: np.ndarray) -> TurnPoses:
    """The same pick and turn, then a carry by ``shift`` (held, at the lift height) before the set-down:
    the set-down, retreat and the pose above it move by ``shift``; the pick is unchanged."""
    d = np.asarray(shift, float)

    def moved(T: np.ndarray) -> np.ndarray:
        out = np.asarray(T, float).copy()
        out[:3, 3] += d
        return out

    tag = f"@{d[0]:+.2f},{d[1]:+.2f}"
    return replace(seq, name=f"{seq.name}{tag}", carry_from=seq.turned_lifted, turned_lifted=moved(seq.turned_lifted),
                   turned=moved(seq.turned), retreat=moved(seq.retreat), above_retreat=moved(seq.above_retreat))


def relocation_shift(seq: TurnPoses) -> np.ndarray | None:
    """The carry of a relocated chain (set-down minus where the turn ended), None for a direct one."""
    if seq.carry_from is None:
        return None
    return np.asarray(seq.turned_lifted, float)[:3, 3] - np.asarray(seq.carry_from, float)[:3, 3]


def closing_azimuth_deg(grasp: Grasp) -> float:
    """Direction (deg about the table normal, mod 180) the pads close along: contact to contact."""
    d = np.asarray(grasp.contacts, float)
    return float(np.degrees(np.arctan2(d[1, 1] - d[0, 1], d[1, 0] - d[0, 0]))) % 180.0


def yaw_tied(grasps: list[Grasp], tolerance_deg: float = 20.0) -> bool:
    """True when every grasp closes along one horizontal direction (a thin box: only across its thickness),
    so the hand's yaw is tied to the object's and where it is set down decides the next grasp's reach."""
    if not grasps:
        return False
    a = np.array([closing_azimuth_deg(g) for g in grasps])
    diff = np.abs((a[:, None] - a[None, :] + 90.0) % 180.0 - 90.0)
    return bool(diff.max() <= tolerance_deg)


def grasp_after(grasp: Grasp, seq: TurnPoses) -> Grasp:
    """The same grasp on the object where ``seq`` leaves it: every pose (and the contacts) moved by the
    object's rigid motion from the pick to the set-down (the turn, plus the carry of a relocated one). Its
    ``turn*`` poses then turn about the new centre: the motion maps the old vertical axis onto the new one.
    What the next view's planner will most likely offer again: the two-step look-ahead checks its chain."""
    move = np.asarray(seq.turned, float) @ np.linalg.inv(np.asarray(seq.grasp, float))
    contacts = np.asarray(grasp.contacts, float) @ move[:3, :3].T + move[:3, 3]
    poses = {name: Pose.from_matrix(move @ p.matrix(), p.frame) for name, p in grasp.poses.items()}
    return replace(grasp, contacts=contacts, poses=poses)


#: Steps of a direct chain whose failure a relocated set-down may cure: the pick was reachable.
RELOCATABLE_STEPS = frozenset({"turn", "set down", "retreat", "up"})

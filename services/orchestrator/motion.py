"""The arm's side of an acquisition: transits without a motion planner, escapes, and one pick-turn-place.

Split out of the state machine (``machine.py`` decides *what* to do next; this module knows *how* the hand
gets there safely). Near the object the hand moves only on straight lines; joint-space motions happen
above the object's top; a pick-turn-place is dry-run in full before the hand sets off (``check_turn``).
The journal writes a turn needs before its irreversible steps are the state machine's: they come in as
the ``on_intent`` / ``on_turned`` callbacks, so this module does no bookkeeping of its own.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from common.api import MoveResult
from common.errors import ObjscanError, RemoteError
from common.messages import Grasp
from common.stroke import STROKE, near_stroke
from services.grasp.pitch import pitched
from services.orchestrator.cell import Cell
from services.orchestrator.config import TurnMotion
from services.orchestrator.limits import ARM_UNAVAILABLE_CODES
from services.orchestrator.planning import ChainMove, TurnPoses
from services.orchestrator.regrasp import relocation_shift

#: m the gripper opens at most before a grasp (its stroke is 0.106 m).
FULL_OPENING = 0.105
#: m a pitched pick opens at least. Tilted against the box's faces the open pads reach into it, and wide open
#: they push it out as they close. The window is narrow, measured on the 5.4 cm slab's 35-degree pick (its
#: registered view): opened to width and margin (9.4 cm) the twin's pad check found the pads cutting it in 13
#: of 20 placements within 2 mm and 1 degree (two picks in a row failed on contact in MuJoCo); in MuJoCo at
#: 9.6 cm it was held, quarter-turned and stood upright as planned (alone, then in a whole run); alone at 9.8 and
#: 10.0 cm it slid out of the pads while lifting; in whole runs at 10.0 and 10.5 cm it was reported held, then
#: found 4.5 cm farther out, unturned (why the two disagree is not established).
PITCHED_OPENING = 0.096


def pick_opening(width: float, margin: float, is_pitched: bool) -> float:
    """How far the gripper opens before closing on a grasp ``width`` wide (see ``PITCHED_OPENING``).

    A level grasp near the stroke (``common.stroke``) opens the whole stroke: on a 9.9 cm box the last
    millimetre is a third of the room the camera's location error leaves the pads."""
    if not is_pitched and near_stroke(width):
        return STROKE
    opening = width + margin
    return min(FULL_OPENING, max(opening, PITCHED_OPENING) if is_pitched else opening)


#: rad: the most any joint may turn in one joint-space chord of a held arc (``ChainMove.joint``). A 10-degree chord
#: through the wrist's singularity turns joint 5 by about 0.5 rad; more means the IK answered another branch
#: and the held object would swing.
MAX_CHORD_JOINT_STEP = 0.7


def move_kind(mv: ChainMove) -> str:
    """The arm's move kind for one move of a chain: a joint-space move or a straight line."""
    return "pose" if mv.joint else "linear"


def check_chord(mv: ChainMove, q_from: np.ndarray, q_to: np.ndarray) -> None:
    """Refuse a joint-space chord whose IK answer is another branch (``MAX_CHORD_JOINT_STEP``)."""
    if not mv.joint:
        return
    step = float(np.max(np.abs(np.asarray(q_to, float) - np.asarray(q_from, float))))
    if step > MAX_CHORD_JOINT_STEP:
        raise RemoteError(f"{mv.step}: a joint-space chord would turn a joint {step:.2f} rad (another IK branch)",
                          code="line_discontinuous")


class GraspFailed(ObjscanError):
    """A grasp did not hold the object (slip, nothing between the pads)."""

    code = "grasp_failed"


class ArmMotion:
    """Motions of one acquisition over ``cell`` with the ``TurnMotion`` settings ``motion``.

    ``decide(what, **detail)`` records a decision in the journal; ``on_intent(phase, **fields)`` journals
    where a turn stands before its next irreversible step (``closing``, ``holding``, ``None``: over);
    ``on_turned(seq)`` records a finished turn (the object released where the turn ends).
    ``step`` names the move under way, for the decision that reports a failure.
    """

    def __init__(self, cell: Cell, motion: TurnMotion, decide: Callable[..., None],
                 on_intent: Callable[..., None], on_turned: Callable[[TurnPoses], None]):
        self.cell = cell
        self.m = motion
        self.decide = decide
        self.on_intent = on_intent
        self.on_turned = on_turned
        self.step = ""

    async def check_turn(self, seq: TurnPoses, center: np.ndarray, held_opening: float | None = None) -> np.ndarray:
        """Dry-run one pick-turn-place; returns the joints to stand in above the pre-grasp, or raises.

        The only free choice is the IK branch at ``above_pregrasp``: from there every move is a straight
        line whose dense IK continues the branch. The branches tried: the IK solution nearest the current
        joints, nearest each configured seed (home), and each one's other wrist branch. A branch whose
        wrist rolls run into their limits half-way through the turn is the failure this avoids.
        ``held_opening`` (the grasp's width): the held moves are checked with the fingers closed that far, as
        they will be (closed, a finger link reaches lower than open: on a short box it can meet the table).
        """
        from services.arm.kinematics import wrist_flip

        m = self.m
        state = await self.cell.state()
        seeds = [np.asarray(state.position, float), *(np.asarray(q, float) for q in m.branch_seeds)]
        tried: list[np.ndarray] = []
        last: tuple[str, RemoteError] | None = None
        for seed in seeds:
            try:
                q_a = (await self.cell.move("pose", target=seq.above_pregrasp, q=seed, speed=m.speed_scale,
                                            dry_run=True)).q
            except RemoteError as exc:
                last = last or ("to above pre-grasp", exc)
                continue
            for cand in (q_a, wrist_flip(q_a)):
                if any(np.allclose(cand, t, atol=1e-3) for t in tried):
                    continue
                tried.append(cand)
                step = "to above pre-grasp"
                try:
                    if cand is not q_a:  # the IK polishes the flipped branch and checks it is inside the limits
                        cand = (await self.cell.move("pose", target=seq.above_pregrasp, q=cand,
                                                     speed=m.speed_scale, dry_run=True)).q
                    q = cand
                    for mv in seq.straight_moves(center):
                        step = mv.step
                        q_next = (await self.cell.move(move_kind(mv), target=mv.target, q=q,
                                                       speed=m.approach_speed_scale, contact=mv.contact, dry_run=True,
                                                       check_opening=held_opening if mv.phase == "held" else None)).q
                        check_chord(mv, q, q_next)
                        q = q_next
                    return np.asarray(cand, float)
                except RemoteError as exc:
                    if exc.code in ARM_UNAVAILABLE_CODES:
                        raise
                    if last is None or last[0] == "to above pre-grasp":  # the farthest a branch got is the news
                        last = (step, exc)
        assert last is not None
        self.step = last[0]
        raise last[1]

    async def transit(self, target: np.ndarray, frame: str, speed: float) -> MoveResult:
        """Move to ``target`` without a motion planner, safest route first.

        1. a straight line (nothing swings down towards the table or the object on the way);
        2. a jerk-limited joint motion (checked sample by sample against table, object box and envelope);
        3. via the home posture (high, camera up): a joint path from there rarely dips.
        Each is fully checked by the arm before it runs; the last failure is raised.
        """
        try:
            return await self.cell.move("linear", target=target, frame=frame, speed=speed)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
        try:
            return await self.cell.move("pose", target=target, frame=frame, speed=speed)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES | {"unreachable", "joint_limits"}:
                raise
            self.decide("transit via home", code=exc.code)
        await self.cell.move("home", speed=speed)
        return await self.cell.move("pose", target=target, frame=frame, speed=speed)

    async def short_move(self, target: np.ndarray, speed: float, contact: bool = True,
                          joint_fallback: bool = False) -> MoveResult:
        """A few centimetres near the object: a straight line; with ``joint_fallback`` a joint motion where
        the line needs a flip (only to get away from the object: near it, a joint motion between nearby
        poses on different IK branches swings the hand far off the line, measured down to the table)."""
        try:
            return await self.cell.move("linear", target=target, speed=speed, contact=contact)
        except RemoteError as exc:
            if not joint_fallback or not exc.code.startswith("line_"):
                raise
            return await self.cell.move("pose", target=target, speed=speed, contact=contact)

    async def escape(self, center: np.ndarray, height: float) -> None:
        """Get the hand clear of the object: back along its approach, then up above the object's top.

        Needed after a failed attempt left the hand close to the object, where every joint-space motion
        would be refused as colliding with the object's box.
        """
        m = self.m
        state = await self.cell.state()
        T = np.asarray(state.T_base_gripper)
        safe_z = height + m.clearance
        if T[2, 3] >= safe_z - 1e-3 or np.linalg.norm(T[:2, 3] - center[:2]) > 0.2:
            return
        back = T.copy()
        back[:3, 3] -= T[:3, 0] * 0.09
        up = T.copy()
        up[2, 3] = max(up[2, 3], safe_z)
        back_up = back.copy()
        back_up[2, 3] = max(back_up[2, 3], safe_z)
        up_low = T.copy()  # clear of the top by less, where the hand pointing down reaches no higher (TurnMotion)
        up_low[2, 3] = max(up_low[2, 3], height + m.low_clearance)
        for route in ((back, back_up), (up,), (up_low,)):
            try:
                for target in route:
                    await self.short_move(target, m.approach_speed_scale, joint_fallback=True)
                return
            except RemoteError as exc:
                self.decide("escape route failed", code=exc.code)
        # no straight way out: home by a joint motion, allowed through the object's box (there is no motion
        # planner to go around it; in the twin the hand cannot topple the object)
        self.decide("escaping through the object box to home")
        await self.cell.clear_object_box()
        await self.cell.move("home", speed=m.approach_speed_scale)

    async def execute_turn(self, grasp: Grasp, seq: TurnPoses, q_start: np.ndarray, box_c: np.ndarray,
                            box_e: np.ndarray, center: np.ndarray, height: float) -> None:
        """Pick, lift, turn about the table normal, set down, release, retreat. Raises on failure.

        ``q_start`` is the checked branch above the pre-grasp (``check_turn``); every later move is the
        straight line the check planned. Motions before the gripper closes may fail harmlessly (RemoteError:
        the caller tries the next pose); a failure while holding sets the object back down where the hand
        is before re-raising.
        """
        c, m = self.cell, self.m
        opening = pick_opening(grasp.width, m.open_margin, pitched(seq.name))
        self.step = "open"
        await c.gripper(opening, m.gripper_force)
        await self.escape(center, height)
        await c.set_object_box(box_c, box_e)
        self.step = "to above pre-grasp"
        await self.transit_joints(q_start, m.speed_scale)
        moves = seq.straight_moves(center)
        for mv in (mv for mv in moves if mv.phase == "approach"):
            self.step = mv.step
            await c.move("linear", target=mv.target, speed=m.approach_speed_scale, contact=mv.contact)
        self.step = "close"
        held_moves = [mv for mv in moves if mv.phase == "held"]
        release_T = np.asarray(held_moves[-1].target if held_moves else seq.above_pregrasp, float)
        shift = relocation_shift(seq)
        self.on_intent("closing", direction=seq.direction, opening=opening,
                       shift=None if shift is None else shift.tolist(),
                                  release_T=release_T.tolist(), center=np.asarray(center, float).tolist(),
                                  height=float(height))
        held = await c.gripper(0.0, m.gripper_force)
        if not held.holding:
            await c.gripper(opening, m.gripper_force)
            self.on_intent(None)
            await self.escape(center, height)
            raise GraspFailed(held.reason or "nothing between the pads")
        self.on_intent("holding")
        await c.clear_object_box()
        try:
            for mv in held_moves:
                # the turn follows the arc in 5-degree chords, each a straight line continuing the branch
                self.step = f"{mv.step} (holding)"
                if mv.joint:  # the IK's answer from here is checked again before the arm follows it
                    q_now = np.asarray((await c.state()).position, float)
                    check_chord(mv, q_now, (await c.move("pose", target=mv.target, q=q_now, contact=True,
                                                         dry_run=True)).q)
                await c.move(move_kind(mv), target=mv.target, speed=m.approach_speed_scale, contact=True)
        except RemoteError:
            await self.set_down_here(m.lift)
            await c.gripper(opening, m.gripper_force)
            self.on_intent(None)
            await self.escape(center, height)
            raise
        await c.gripper(opening, m.gripper_force)
        self.on_turned(seq)  # the turn happened: journalled before the retreat
        self.step = "retreat"
        try:
            for mv in (mv for mv in moves if mv.phase == "released"):
                await c.move("linear", target=mv.target, speed=m.approach_speed_scale, contact=True)
        except RemoteError as exc:  # the object is turned and released: escape as well as we can
            self.decide("retreat failed; escaping", code=exc.code)
            await self.escape(center, height)
        # the object now stands where the set-down put it (moved by a relocated one)
        await c.set_object_box(box_c if shift is None else box_c + shift, box_e)

    async def transit_joints(self, q: np.ndarray, speed: float) -> MoveResult:
        """Joint motion to a checked configuration; via the home posture when the direct one is refused."""
        try:
            return await self.cell.move("joints", q=q, speed=speed)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
            self.decide("transit via home", code=exc.code)
        await self.cell.move("home", speed=speed)
        return await self.cell.move("joints", q=q, speed=speed)

    async def set_down_here(self, lift: float) -> None:
        """While holding, lower the hand by ``lift`` where it is (the object back on the table)."""
        state = await self.cell.state()
        T = np.asarray(state.T_base_gripper).copy()
        T[2, 3] -= lift
        try:
            await self.short_move(T, self.m.approach_speed_scale)
        except RemoteError as exc:
            self.decide("could not lower the object before releasing it", code=exc.code)

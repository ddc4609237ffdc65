"""The acquisition state machine: locate → (scan → register → plan grasp → turn) × views → model → done.

States and their allowed transitions are declared in ``states.TRANSITIONS`` (drawn in docs/orchestrator.md); a
transition outside it is a bug and stops the run. Every state's outputs are written to the session folder
and the journal before the next state starts, so a killed orchestrator resumes at the state it was in
and re-uses every frame already captured (scans are never captured twice, and never overwritten: a
re-scan first moves the old attempt aside).

This module drives; every other job of an acquisition is a small module it calls: the records of the
irreversible steps (``turn_journal``), the cell made ready (``cell_setup``), the scan poses the arm reaches
(``scan_reach``), the arm's motions (``motion``), the pair work sent to registration (``incremental``), the
ground-truth evaluation (``ground_truth``), ``report.json`` (``session_report``) and the library insert
(``library_insert``).

Recovery, as a robot on a real table needs it:
- an unreachable or colliding motion tries the grasp's next angular offset, then the next grasp;
- a failed grasp (slip, nothing between the pads) opens, backs off, re-scans and re-plans;
- frontal grasps that all fail to execute fall back to top-down ones;
- after ``max_rescans`` of one view the arm goes home with the gripper open and the run ends with a reason;
- an e-stop from anywhere halts the arm at once and parks the machine in ``stopped`` (resumable).

Irreversible steps are journalled before they start and when they end, so a resume after a crash knows what
already happened: a re-scan writes
``pending_rescan`` before it moves the old attempt aside; a turn writes ``turn_intent`` before the gripper
closes (phase ``closing``), when the object is held (``holding``), and its completion (the new view and its
commanded turn) right after the release, before the retreat. A resume first settles an open intent with what
the arm reports (``_recover_turn``): a turn that finished physically is recorded, not repeated; an object still
held is set down before the gripper opens; a turn cut off half-way re-scans the view.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from common.api import GraspPlanReply, ViewResult
from common.errors import ObjscanError, RemoteError
from common.log import event
from common.messages import Grasp
from services.orchestrator.cell import Cell
from services.orchestrator.cell_setup import prepare_cell
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.ground_truth import evaluate_against_twin, journal_accuracy
from services.orchestrator.incremental import IncrementalModel
from services.orchestrator.journal import Journal
from services.orchestrator.lay_down import LAY_DOWN
from services.orchestrator.lay_down_step import record_laid_down, try_lay_down
from services.orchestrator.library_insert import insert_session_model_async
from services.orchestrator.limits import ARM_UNAVAILABLE_CODES, name_limit, name_scan_pose_limit
from services.orchestrator.motion import ArmMotion, GraspFailed, pick_opening
from services.orchestrator.pitched_turn import QUARTER_TURN
from services.orchestrator.pitched_turn_step import try_pitched_turn
from services.orchestrator.planning import (
    TurnPoses,
    look_pose,
    object_box,
    radial_offset_deg,
    turn_sequences,
)
from services.orchestrator.push_step import measure_push, try_push
from services.orchestrator.recovery import grasp_order, lies_down, plan_mode
from services.orchestrator.regrasp import (
    RELOCATABLE_STEPS,
    grasp_after,
    relocated,
    relocation_shift,
    relocation_shifts,
    yaw_tied,
)
from services.orchestrator.reposition import NO_TURN, drift, favoured_spots, reposition_shifts, without_turn
from services.orchestrator.scan_reach import first_reachable_scan_set, scannable_spot
from services.orchestrator.session_report import acquisition_report, model_lateness_s, write_report
from services.orchestrator.states import TERMINAL, TRANSITIONS, State
from services.orchestrator.topple import topple_reason
from services.orchestrator.turn_journal import TurnJournal, released_at
from services.orchestrator.views_aside import set_views_aside
from services.registration.api import with_turn_accuracy
from services.session_store import SessionStore

log = logging.getLogger("objscan.orchestrator")

SCANS_PER_VIEW = 3
__all__ = ["Acquisition", "AcquisitionFailed", "State", "TERMINAL", "TRANSITIONS"]


class AcquisitionFailed(ObjscanError):
    """The acquisition cannot go on (e.g. no grasp after every re-scan); the reason is in the message."""

    code = "acquisition_failed"


class Acquisition:
    """One acquisition over a ``Cell``, persisted in a ``SessionStore``; ``run()`` drives it to the end."""

    def __init__(self, cell: Cell, store: SessionStore, config: AcquisitionConfig,
                 on_status: Callable[[dict[str, Any]], None] | None = None, library: Path | None = None):
        self.cell = cell
        self.library = library
        self.store = store
        self.config = config
        self.on_status = on_status or (lambda _s: None)
        self.stop_requested = asyncio.Event()
        journal = store.load_journal()
        self.resumed = journal is not None
        self.j = Journal.from_dict(journal) if journal is not None else Journal(config=config.to_dict())
        if self.resumed:
            self.config = AcquisitionConfig.from_dict(self.j.config)
            self.decide("resumed", state=self.j.state, view=self.j.view)
        self.turns = TurnJournal(self.j, store, self.config.turn_deg)
        if self.resumed and self.j.pending_rescan:  # killed while moving the old attempt aside: finish it
            self.turns.finish_rescan()
            self.j.state = State.SCAN.value
        self._plan: GraspPlanReply | None = None
        self.motion = ArmMotion(cell, self.config.turn, self.decide, self.turns.intent,
                                lambda seq: self._record_release(self.view, seq.direction, relocation_shift(seq)))
        self.incremental = IncrementalModel(store, self.config.dynamic_config, cell,
                                            enabled=self.config.incremental, decide=self.decide)

    # -------------------------------------------------------------------------------- bookkeeping
    async def _dry_run(self, k: int, chain: TurnPoses, center: np.ndarray, width: float,
                       failures: list[str]) -> np.ndarray | None:
        """The chain's start configuration if the arm can run it whole, else None with the refusal recorded
        (in ``failures`` and view ``k``'s limits). An e-stop or a busy arm is not a refusal: it propagates."""
        try:
            return await self.motion.check_turn(chain, center, width)
        except RemoteError as exc:
            if exc.code in ARM_UNAVAILABLE_CODES:
                raise
            failures.append(f"{chain.name}:{exc.code}")
            self._limits(k).setdefault("dry_run", []).append(exc.code)
            return None

    def _record_release(self, k: int, direction: int, shift: np.ndarray | None) -> None:
        """The object is released where a move ends: laid on its side restarts the views where it lies
        (``record_laid_down``); a turn or a reposition is the turn journal's (``TurnJournal.record_turn``)."""
        if direction == LAY_DOWN:
            record_laid_down(self, k)
        else:
            self.turns.record_turn(k, direction, shift)

    @property
    def state(self) -> State:
        return State(self.j.state)

    @property
    def view(self) -> int:
        return int(self.j.view)

    def decide(self, what: str, **detail: Any) -> None:
        """Record a decision (and log it): the journal says why the run went the way it did."""
        entry = {"t": round(time.time() - self.j.started, 3), "state": self.j.state, "view": self.j.view,
                 "what": what, **{k: v for k, v in detail.items()}}
        self.j.decisions.append(entry)
        fields = {"view": self.j.view, **{k: v for k, v in detail.items() if not isinstance(v, (dict, list))}}
        event(log, what, **fields)

    def status(self) -> dict[str, Any]:
        views_done = sum(1 for k in range(self.config.views) if self.store.has_view(k))
        return {"state": self.j.state, "view": self.view, "views": self.config.views, "views_done": views_done,
                "status": self.j.status, "attempts": self.j.counters.grasp_attempts,
                "rescans": self.j.counters.rescans, "last_error": self.j.error,
                "session": str(self.store.path), "elapsed_s": round(time.time() - self.j.started, 1),
                "model": self.j.model_path, "accuracy": self.j.accuracy,
                "accepted": self.j.model_accepted, "why": self.j.model_why,
                "turns_deg": list(self.j.turns_deg)}  # cumulative commanded turn per view (the live view)

    def _persist(self) -> None:
        self.store.save_journal(self.j.to_dict())
        turns = self.j.turns_deg
        views_done = sum(1 for k in range(len(turns)) if self.store.has_view(k) or self.store.has_scan(k, 0))
        self.store.write_session_info(self.j.config, max(views_done, 1), turns,
                                      {"simulated": self.j.simulated})
        self.on_status(self.status())

    def _go(self, nxt: State) -> None:
        cur = self.state
        # nxt == cur: the step already journalled its own outcome (a turn records the next view at release)
        if nxt != cur and nxt not in TERMINAL and nxt not in TRANSITIONS.get(cur, set()):
            raise AcquisitionFailed(f"internal error: no transition {cur.value} -> {nxt.value}")
        self.j.state = nxt.value
        self._persist()

    # -------------------------------------------------------------------------------- main loop
    async def run(self) -> dict[str, Any]:
        handlers = {State.LOCATE: self.locate, State.SCAN: self.scan, State.REGISTER: self.register,
                    State.PLAN_GRASP: self.plan_grasp, State.TURN: self.turn, State.MODEL: self.model}
        after_estop = self.state == State.STOPPED
        if after_estop:  # resuming after an e-stop
            self.j.state = self.j.stopped_in or State.SCAN.value
        if self.state == State.DONE:  # nothing to do, but say so: a follower waits for a final status
            self.decide("resume of a finished session: nothing to do")
            self._persist()
            return self.status()
        if self.state == State.FAILED:  # the summary says "resume with ...": retry where it failed
            self._retry_after_failure()
        self.j.status = "running"
        try:
            self._persist()
            if after_estop:
                await self.cell.reset_estop()
            if self.j.turn_intent:  # before anything opens the gripper: it may hold the object
                await self._recover_turn()
            await prepare_cell(self.cell, self.config, self.j, self.decide)
            while self.state not in TERMINAL:
                if self.stop_requested.is_set():
                    raise asyncio.CancelledError
                state = self.state
                t0 = time.perf_counter()
                nxt = await handlers[state]()
                self.j.timings_s[state.value] = round(self.j.timings_s.get(state.value, 0.0)
                                                         + time.perf_counter() - t0, 3)
                self._go(nxt)
            self.j.status = "done"
        except asyncio.CancelledError:
            self.j.stopped_in = self.j.state
            self.j.state, self.j.status = State.STOPPED.value, "stopped"
            self.decide("stopped", reason="stop requested")
        except ObjscanError as exc:
            await self._fail(exc.code, exc.message)
        except OSError as exc:  # the session folder cannot be written (disk full, removed, read-only)
            await self._fail("disk_full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else "io_error",
                             f"{type(exc).__name__}: {exc}")
        except Exception as exc:  # a bug must end the session visibly, not leave it 'running' forever
            await self._fail("internal", f"{type(exc).__name__}: {exc}")
        self.incremental.close()
        self._persist_final()
        return self.status()

    def _persist_final(self) -> None:
        """The last write of a run. It must not raise (the failure path raising left journals ``running``):
        if the folder cannot take it, the session ends ``failed`` and the journal alone is written with the
        space the store set aside."""
        try:
            self._persist()
            return
        except OSError as exc:
            code = "disk_full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else "io_error"
            if self.j.status != "failed":
                self.j.error = {"code": code, "message": f"{type(exc).__name__}: {exc}", "state": self.j.state}
                self.j.state, self.j.status = State.FAILED.value, "failed"
            else:
                self.j.error["persist_error"] = f"{type(exc).__name__}: {exc}"
            self.decide("could not write the session folder", code=code)
        try:
            self.store.save_journal(self.j.to_dict(), last_resort=True)
        except OSError as exc:
            event(log, "the journal could not be written", logging.ERROR, error=repr(exc))
        self.on_status(self.status())

    def _retry_after_failure(self) -> None:
        """Resume a failed session from the state it failed in, with a fresh re-scan budget for that view
        (the arm was parked, gripper open, when it failed: nothing is held)."""
        err = self.j.error or {}
        state = err.get("state") if err.get("state") in {s.value for s in State} - {s.value for s in TERMINAL} \
            else State.SCAN.value
        self.j.state = state
        self.j.rescans.pop(str(self.view), None)
        self.j.previous_errors.append(err)
        self.j.error = None
        self.decide("resumed after failure", state=state, previous=err.get("code"))

    async def _fail(self, code: str, message: str) -> None:
        """End the session ``failed`` with the reason in the journal, and park the arm."""
        self.j.error = {"code": code, "message": message, "state": self.j.state}
        self.j.state, self.j.status = State.FAILED.value, "failed"
        self.decide("failed", code=code, message=message)
        await self._park()

    async def _park(self) -> None:
        """Arm home with the gripper open: the safe state after a failure."""
        for step in (lambda: self.cell.gripper(0.1), lambda: self.cell.clear_object_box(),
                     lambda: self.cell.move("home", speed=0.3)):
            try:
                await step()
            except ObjscanError as exc:
                self.decide("park step failed", code=exc.code, message=exc.message)
            except Exception as exc:  # parking is best effort: every step is tried, whatever the last did
                self.decide("park step failed", code="internal", message=repr(exc))

    # -------------------------------------------------------------------------------- states
    async def locate(self) -> State:
        """Look at the workspace, find the goal object (cluster nearest the image centre), estimate it."""
        T = look_pose(self._workspace_center(), self.config.scan)
        await self.cell.move("pose", target=T, frame="camera", speed=0.6)
        frame = await self.cell.capture(self.config.width, self.config.height)
        self.j.counters.captures += 1
        from common.session_folder import write_scan

        write_scan(self.store.path / "locate", 0, 0, frame)
        result = await self.cell.register_static([frame], view=-1, profile=self.config.static_profile,
                                                 pose_accuracy=self.config.pose_accuracy)
        self._remember_object(-1, result)
        self.decide("located", center=np.round(result.center, 4).tolist(), height=round(result.height, 4))
        return State.SCAN

    def _remember_object(self, view: int, result: ViewResult) -> None:
        self.j.centers[str(view)] = np.asarray(result.center, float).tolist()
        self.j.heights[str(view)] = float(result.height)

    def _object_estimate(self, view: int) -> tuple[np.ndarray, float]:
        """Best current estimate of the object's footprint centre and height (latest registered view)."""
        for k in range(view, -2, -1):
            if str(k) in self.j.centers:
                return np.asarray(self.j.centers[str(k)]), float(self.j.heights[str(k)])
        return self._workspace_center(), 0.1

    def _workspace_center(self) -> np.ndarray:
        x, y = self.config.workspace_center
        return np.array([float(x), float(y), 0.0])

    async def _reachable_scan_set(self, view: int) -> list[np.ndarray]:
        key = str(view)
        if key in self.j.scan_sets:
            return [np.asarray(T) for T in self.j.scan_sets[key]]
        # the latest estimate: view k's own when a relocated set-down recorded where it now stands
        center, height = self._object_estimate(view if view > 0 else -1)
        if view > 0:  # dry runs plan from the current posture: start them from the high home posture
            await self.motion.escape(center, height)
            try:
                await self.cell.move("home", speed=0.6)
            except RemoteError as exc:
                self.decide("could not go home before choosing scan poses", code=exc.code)
        candidate, reasons = await first_reachable_scan_set(self.cell, self.config.scan, center, height)
        if candidate is not None:
            self.j.scan_sets[key] = [T.tolist() for T in candidate]
            return candidate
        raise AcquisitionFailed(f"view {view}: no reachable set of scan poses around the object; "
                                f"limit: {name_scan_pose_limit(reasons)}",
                                detail={"center": center.tolist(), "reasons": reasons[:6], "limit": "reach"})

    async def _scannable_spot(self, spot: np.ndarray, height: float, cache: dict[tuple, bool]) -> bool:
        """Whether the object set down at ``spot`` can be scanned there (``scan_reach.scannable_spot``)."""
        return await scannable_spot(self.cell, self.config.scan, spot, height, cache, self.decide)

    async def scan(self) -> State:
        k = self.view
        poses = await self._reachable_scan_set(k)
        for j, T in enumerate(poses):
            if self.store.has_scan(k, j):
                continue  # captured before a restart: never capture twice
            moved = await self.motion.transit(T, "camera", 0.6)
            frame = await self.cell.capture(self.config.width, self.config.height)
            self.j.counters.captures += 1
            self.store.save_scan(k, j, frame, {"joints": {"position": moved.q.tolist()}, "view": k, "scan": j,
                                               "commanded_turn_deg": self.j.turns_deg[k]})
            self._persist()
        return State.REGISTER

    async def register(self) -> State:
        k = self.view
        if not self.store.has_view(k):
            frames = [self.store.load_scan(k, j) for j in range(SCANS_PER_VIEW)]
            try:
                async with self.incremental.foreground():  # no speculative pair job meanwhile
                    result = await self.cell.register_static(frames, view=k, profile=self.config.static_profile,
                                                             pose_accuracy=self.config.pose_accuracy)
            except RemoteError as exc:
                self.decide("static registration failed", code=exc.code, message=exc.message)
                return await self._rescan(k, f"registration failed: {exc.code}")
            left_out = result.figures.get("scans_left_out") or []
            if left_out:  # a scan failed its check or its correction is beyond the arm's accuracy: not fused
                which = ", ".join(f"scan {e['index']} ({e['reason']})" for e in left_out)
                if int(self.j.rescans.get(str(k), 0)) < self.config.max_rescans:
                    self.decide("scans not fused: taking the view again", view=k, left_out=left_out)
                    return await self._rescan(k, f"not fused: {which}")
                self.decide("view kept without the scans that could not be fused (re-scans used up)", view=k,
                            left_out=left_out)
            reason = (topple_reason(self.j.heights.get(str(k - 1)), float(result.height),
                                    self.config.topple_height_tol_m, self.config.topple_height_rel, k)
                      if k > 0 else None)
            if reason is not None:
                return self._restart_after_topple(k, reason, result)
            restart = measure_push(self, k, result)  # a view scanned after a push: its turn is measured here
            if restart is not None:
                return restart
            self.store.save_view(result)
            self._remember_object(k, result)
            self.decide("view registered", points=len(result.cloud),
                        seconds=result.figures.get("timings_s", {}).get("total"))
        self.incremental.view_ready(k, self.j.turns_deg)  # pair k-1 -> k in the background, never awaited here
        if k >= self.config.views - 1:
            return State.MODEL
        return State.PLAN_GRASP

    def _limits(self, k: int) -> dict[str, Any]:
        """What stood in the way at view ``k`` (planner rejections, dry-run codes, grasp failures)."""
        return self.j.limits_of(k)

    def _restart_after_topple(self, k: int, reason: str, result: ViewResult) -> State:
        """The object toppled before view ``k``: set views 0..k aside (kept on disk) and scan again from
        view 0 where it now lies, so no view of the old resting pose is fused with the new one."""
        n = self.j.topple_restarts + 1
        if n > self.config.max_topple_restarts:
            raise AcquisitionFailed(f"view {k}: {reason}; it toppled again after {n - 1} restart(s) of the views: "
                                    "giving up; limit: stability: the object does not stay standing after a "
                                    f"set-down; recovery tried: {', '.join(self._recoveries_tried(k)) or 'none'}",
                                    detail={"view": k, "restarts": n - 1, "limit": "stability"})
        self.j.topple_restarts = n
        self.j.counters.topple_restarts = n
        set_views_aside(self.store.path, self.j, k, f"toppled{n}", evidence=False)  # its evidence is dropped below
        self.j.view, self.j.turns_deg, self.j.scan_sets, self.j.rescans = 0, [0.0], {}, {}
        self.j.grasp_mode, self.j.failed_grasps, self.j.centers, self.j.heights = "auto", {}, {}, {}
        self.j.turn_direction = None
        self._remember_object(-1, result)
        self._plan = None
        self.decide("object toppled: restarting the views from where it lies", reason=reason, restart=n)
        return State.SCAN

    async def _rescan(self, k: int, reason: str) -> State:
        n = int(self.j.rescans.get(str(k), 0)) + 1
        if n > self.config.max_rescans:
            lim = self.j.limits.get(str(k), {})
            limit = name_limit(lim.get("planner", {}), lim.get("dry_run", []), lim.get("grasp", []))
            tried = self._recoveries_tried(k)
            raise AcquisitionFailed(f"view {k}: giving up after {n - 1} re-scans ({reason}); limit: {limit}; "
                                    f"recovery tried: {', '.join(tried) or 'none'}",
                                    detail={"view": k, "limit": limit.split(":")[0], "recoveries": tried})
        self.j.rescans[str(k)] = n
        self.j.counters.rescans += 1
        self.turns.begin_rescan(k, n)  # intent first, then the old attempt moves aside
        self.decide("re-scan", reason=reason, rescan=n)
        return State.SCAN

    def _recoveries_tried(self, k: int) -> list[str]:
        """The recovery strategies this acquisition went through up to view ``k``, in order, once each:
        re-scans, top-down fallback, relocated set-downs, repositions, re-grasps after slips, topple restarts."""
        out = ["re-scan"] if self.j.rescans.get(str(k)) else []
        if any(d.get("what") == "falling back to top-down grasps" and d.get("view") == k for d in self.j.decisions):
            out.append("top-down grasps")
        for e in self.j.regrasps.get(str(k), []):
            if e.get("strategy") and e["strategy"] not in out:
                out.append(str(e["strategy"]))
        if any(str(d.get("what", "")).startswith("repositioning") and d.get("view") == k for d in self.j.decisions) \
                and "reposition" not in out:
            out.append("reposition (not executable)")
        if any(d.get("what") == "no pitched turn executable" and d.get("view") == k for d in self.j.decisions) \
                and "pitched turn" not in out:
            out.append("pitched turn (not executable)")
        if self.j.topple_restarts:
            out.append(f"restart after topple x{self.j.topple_restarts}")
        if self.j.pushes:
            out.append(f"pushed round x{len(self.j.pushes)}")
        elif any(d.get("what") == "no push executable" and d.get("view") == k for d in self.j.decisions):
            out.append("push (not executable)")
        if (self.j.laid_down or {}).get("state") == "done":
            out.append("laid on its side")
        elif any(d.get("what") == "no lay-down executable" and d.get("view") == k for d in self.j.decisions):
            out.append("lay down (not executable)")
        return out

    async def plan_grasp(self) -> State:
        k = self.view
        view = self.store.load_view(k)
        mode = plan_mode(self.j.grasp_mode, self._lying(view.cloud.xyz, view.height), self._slipped_kinds(k))
        if mode != self.j.grasp_mode:
            self.decide("planning frontal and top-down grasps alike",
                        why="the object lies on its side" if self._lying(view.cloud.xyz, view.height)
                        else "a grasp slipped at this view")
        plan = await self.cell.plan_grasps(view.cloud, view.table, mode)
        self.store.save_json(f"view_{k:02d}/grasps_{mode}.json", {
            "mode": mode, "explanation": plan.explanation, "seconds": plan.seconds, "rejections": plan.rejections,
            "grasps": [{"kind": g.kind, "rank": g.rank, "width": g.width, "contacts": np.asarray(g.contacts).tolist(),
                        "metrics": g.metrics} for g in plan.grasps]})
        self.decide("grasps planned", mode=mode, n=len(plan.grasps), explanation=plan.explanation)
        counts = (plan.rejections or {}).get("counts", {}) if isinstance(plan.rejections, dict) else {}
        planner = self._limits(k).setdefault("planner", {})
        for reason, count in counts.items():
            planner[reason] = planner.get(reason, 0) + int(count)
        if not plan.grasps:
            if mode == "auto":
                self.j.grasp_mode = "top_down"
                return await self._rescan(k, "no grasp found")
            return await self._rescan(k, "no grasp found (top-down)")
        self._plan = plan
        return State.TURN

    def _lying(self, xyz: np.ndarray, height: float) -> bool:
        """The object toppled or was laid down during this acquisition and now lies on its side
        (``recovery.lies_down``)."""
        laid = (self.j.laid_down or {}).get("state") == "done"
        return (self.j.topple_restarts > 0 or laid) and lies_down(xyz, height)

    def _slipped_kinds(self, k: int) -> list[str]:
        """Grasp kinds that slipped at view ``k`` (the re-grasp after a slip tries the others first)."""
        return [str(e["slipped"]) for e in self._regrasps_now(k) if e.get("slipped")]

    def _regrasps_now(self, k: int) -> list[dict[str, Any]]:
        """The strategies journalled at view ``k`` since the views last restarted (a topple restarts them: the
        view ``k`` of before lay otherwise)."""
        return [e for e in self.j.regrasps.get(str(k), []) if int(e.get("restart", 0)) == self.j.topple_restarts]

    def _candidates(self, center: np.ndarray, height: float, xyz: np.ndarray,
                    box: tuple[np.ndarray, np.ndarray]) -> list[tuple[int, Grasp, TurnPoses]]:
        """Every (grasp, offset, direction) of the plan, likeliest first.

        Grasps in ``recovery.grasp_order``: the kind that slipped last, top-down first on a lying object,
        radial-ish grasps before side ones, the safest hold against the centre of mass, then the planner's
        rank. Within a grasp, once the session has turned one way it keeps turning that way (12 views cover
        360 degrees in order); before that, the direction that brings the hand back toward radial goes
        first, then the planner's offset order. ``box``: the object's collision box, which a pre-grasp's open
        fingers must clear (``planning.clear_pregrasp``).
        """
        assert self._plan is not None
        cfg = self.config
        grasps = list(self._plan.grasps)
        offsets = [radial_offset_deg(g, center) for g in grasps]
        order = grasp_order(grasps, self._lying(xyz, height), self._slipped_kinds(self.view), xyz, center, height,
                            [abs(o) > 50.0 for o in offsets])
        fixed = self.j.turn_direction
        footprint = np.asarray(xyz, float)[:, :2]
        out = []
        for gi in order:
            grasp = self._plan.grasps[gi]
            clear = (box, footprint, pick_opening(grasp.width, cfg.turn.open_margin, False))
            sequences = sorted(turn_sequences(grasp, cfg.turn, height, clear),
                               key=lambda sq: (fixed is not None and sq.direction != fixed,
                                               abs(offsets[gi] + sq.direction * cfg.turn_deg)))
            out += [(gi, grasp, sq) for sq in sequences if fixed is None or sq.direction == fixed]
        return sorted(out, key=lambda c: c[2].low_above)  # the lowered ones after every other grasp's

    async def _attempt(self, k: int, gi: int, grasp: Grasp, seq: TurnPoses, q_start: np.ndarray,
                       box: tuple[np.ndarray, np.ndarray], signature: str, failures: list[str]) -> State | None:
        """Execute one checked pick-turn-place: the next state, or None when the arm refused a move before
        the object was held (the caller tries the next chain)."""
        view = self.store.load_view(k)
        box_c, box_e = box
        self.j.counters.grasp_attempts += 1
        try:
            await self.motion.execute_turn(grasp, seq, q_start, box_c, box_e, view.center, view.height)
        except GraspFailed as exc:
            self.j.counters.slips += 1
            self.j.failed_grasps.setdefault(str(k), []).append(signature)
            self._limits(k).setdefault("grasp", []).append(exc.message.split(":")[0][:40])
            height = float(np.asarray(grasp.contacts, float)[:, 2].mean())
            self.j.regrasps.setdefault(str(k), []).append(
                {"strategy": "re-grasp after slip", "slipped": grasp.kind, "pose": seq.name,
                 "contact_height": round(height, 4), "restart": self.j.topple_restarts})
            self.decide("grasp failed", grasp=gi, pose=seq.name, reason=exc.message,
                        next="re-grasp: the other kind first, then lower grasps")
            self._plan = None
            self.j.grasp_mode = "auto"
            return await self._rescan(k, f"grasp failed: {exc.message}")
        except RemoteError as exc:
            failures.append(f"{seq.name}:{exc.code}")
            self.decide("grasp pose not executable", grasp=gi, pose=seq.name, step=self.motion.step,
                        code=exc.code, message=exc.message[:200])
            return None
        shift = relocation_shift(seq)
        if seq.direction == LAY_DOWN:  # already journalled at the release (``record_laid_down``)
            self._plan = None
            return State.SCAN
        if seq.direction == NO_TURN or abs(seq.direction) == QUARTER_TURN:  # journalled at the release
            self.decide("repositioned: picked and set down " + ("without a turn" if seq.direction == NO_TURN else
                                                                "turned a quarter turn")
                        + "; the view is scanned again there",
                        grasp=gi, pose=seq.name, kind=grasp.kind, to=self.j.centers.get(str(k), [0, 0])[:2],
                        shift=None if shift is None else np.round(shift[:2], 3).tolist())
            self._plan = None
            return State.SCAN
        if shift is not None:
            self.j.counters.regrasps += 1
            self.j.regrasps.setdefault(str(k), []).append(
                {"strategy": "relocated set-down", "pose": seq.name, "shift": np.round(shift, 4).tolist()})
        self.decide("turned", grasp=gi, pose=seq.name, kind=grasp.kind, direction=seq.direction,
                    relocated=None if shift is None else np.round(shift[:2], 3).tolist())
        self._plan = None
        return State.SCAN  # already journalled at the release (``TurnJournal.record_turn``)

    async def _next_turn_possible(self, grasp: Grasp, seq: TurnPoses, center: np.ndarray) -> bool:
        """Dry-run the turn after this one: the same grasp where ``seq`` leaves the object, turned again the
        same way, directly or by a relocated set-down. A thin box set down where no next grasp reaches it
        cannot be turned again (its pick fails whatever the set-down), so such a spot is avoided now."""
        nxt = grasp_after(grasp, seq)
        shift = relocation_shift(seq)
        new_center = np.asarray(center, float) + (0.0 if shift is None else shift)
        for nseq in turn_sequences(nxt, self.config.turn, float(self.j.heights.get(str(self.view), 0.1))):
            if nseq.direction != seq.direction:
                continue
            try:
                await self.motion.check_turn(nseq, new_center, float(grasp.width))
                return True
            except RemoteError as exc:
                if exc.code in ARM_UNAVAILABLE_CODES:
                    raise
                if self.motion.step in RELOCATABLE_STEPS:  # its pick reaches: a relocation may finish it
                    for d in relocation_shifts(new_center, self.config.turn.relocation)[:2]:
                        try:
                            await self.motion.check_turn(relocated(nseq, d), new_center, float(grasp.width))
                            return True
                        except RemoteError as exc2:
                            if exc2.code in ARM_UNAVAILABLE_CODES:
                                raise
        return False

    async def turn(self) -> State:
        k = self.view
        if self._plan is None:  # resumed here: the plan is re-made from the registered view
            return State.PLAN_GRASP
        cfg = self.config
        view = self.store.load_view(k)
        box_c, box_e = object_box(view.center, view.height, view.cloud.xyz, cfg.turn.object_box_margin)
        failures: list[str] = []
        attempts = checks = 0
        failed_before = set(self.j.failed_grasps.get(str(k), []))
        await self.motion.escape(view.center, view.height)
        await self.cell.set_object_box(box_c, box_e)
        direct = self._candidates(view.center, view.height, view.cloud.xyz, (box_c, box_e))
        chains = list(direct)
        moved = await self._reposition(k, view.center, view.height, chains, (box_c, box_e), failures, proactive=True)
        if moved is not None:
            return moved
        late: list[tuple[int, Grasp, TurnPoses]] = []  # picks that were reachable; the turn or set-down was not
        relocations = 0
        scannable: dict[tuple, bool] = {}  # relocation spots: can the object be scanned there?
        shifts = relocation_shifts(view.center, cfg.turn.relocation)
        tied = yaw_tied(list(self._plan.grasps)) and bool(shifts)
        fallback: tuple[int, Grasp, TurnPoses, np.ndarray] | None = None  # passed its check, not the look-ahead
        if tied:  # a thin box: where it is set down decides whether its next grasp is reachable
            moved = [(gi, g, relocated(sq, d)) for d in shifts for gi, g, sq in direct]  # nearest spot first
            far = float(np.hypot(*view.center[:2])) > cfg.turn.relocation.near_radius + cfg.turn.relocation.min_shift
            # farther than the near ring: bring it in first; on the ring, top-down turns reach every yaw there
            # (measured), so it moves again only once those have been tried too
            # on the ring but off its spot (each turn about the estimated centre leaves it a centimetre or so
            # off, and a lying 24 cm box drifted 4 cm in eight turns, past the wrist's reach), the turn sets it
            # back on the spot first
            off_spot = not far and float(np.linalg.norm(shifts[0])) < cfg.turn.relocation.reposition_drift
            back, rest = (moved[:len(direct)], moved[len(direct):]) if off_spot else ([], moved)  # to shifts[0]
            direct = moved + direct if far else back + direct + rest if self.j.grasp_mode == "top_down" \
                else back + direct
            direct.sort(key=lambda c: c[2].low_above)  # the lowered ones after every other, relocated or not
            self.decide("yaw-tied grasps: relocated set-downs tried " + ("first" if far else "back on the spot first"
                                                                        if back else "after direct ones"
                                                                        if self.j.grasp_mode == "top_down" else
                                                                        "after the top-down ones"),
                        chains=len(direct), spots=[np.round(view.center[:2] + d[:2], 3).tolist() for d in shifts])
        for phase in ("direct", "relocated"):
            if phase == "relocated" and tied:
                break
            if phase == "relocated":
                if not late or not shifts:
                    break
                self.decide("trying relocated set-downs", chains=len(late),
                            spots=[np.round(d[:2], 3).tolist() for d in shifts])
                direct = sorted(((gi, g, relocated(sq, d)) for d in shifts for gi, g, sq in late),  # nearest first
                                key=lambda c: c[2].low_above)
            for gi, grasp, seq in direct:
                signature = f"{grasp.kind}:{gi}:{seq.name}"
                relocating = seq.carry_from is not None
                if attempts >= cfg.max_grasp_attempts or (checks >= cfg.turn.max_checks and not relocating) \
                        or relocations >= cfg.turn.relocation.max_checks:
                    break
                if signature in failed_before:  # it slipped before: after a re-scan, try another one first
                    continue
                # the whole pick-turn-place is planned and checked before the hand moves: an attempt that would
                # stop half-way (a joint limit in the middle of the turn) would leave the object part-turned,
                # and every later attempt would work on a view that no longer matches it
                if relocating and not await self._scannable_spot(
                        view.center + relocation_shift(seq), view.height, scannable):
                    continue
                checks += 1
                relocations += relocating
                self.j.counters.grasp_checks += 1
                try:
                    q_start = await self.motion.check_turn(seq, view.center, float(grasp.width))
                except RemoteError as exc:
                    failures.append(f"{seq.name}:{exc.code}")
                    self._limits(k).setdefault("dry_run", []).append(exc.code)
                    self.decide("grasp pose not executable", grasp=gi, pose=seq.name, step=self.motion.step,
                                code=exc.code, message=exc.message[:200], dry_run=True)
                    if not relocating and self.motion.step in RELOCATABLE_STEPS:
                        late.append((gi, grasp, seq))
                    continue
                if tied and k + 1 < cfg.views - 1:  # two-step look-ahead: will the next view turn too?
                    if fallback is None:
                        fallback = (gi, grasp, seq, q_start)
                    if not await self._next_turn_possible(grasp, seq, view.center):
                        self.decide("set-down leaves no executable next turn: trying another", grasp=gi,
                                    pose=seq.name)
                        continue
                    try:  # the next chain's check took another branch: the start of this one is found again
                        q_start = await self.motion.check_turn(seq, view.center, float(grasp.width))
                    except RemoteError as exc:
                        failures.append(f"{seq.name}:{exc.code}")
                        continue
                attempts += 1
                outcome = await self._attempt(k, gi, grasp, seq, q_start, (box_c, box_e), signature, failures)
                if outcome is not None:
                    return outcome
        if fallback is not None and attempts < cfg.max_grasp_attempts:
            gi, grasp, seq, _ = fallback
            self.decide("no set-down keeps the next turn executable: taking the first executable one",
                        grasp=gi, pose=seq.name)
            try:
                q_start = await self.motion.check_turn(seq, view.center, float(grasp.width))
            except RemoteError as exc:
                failures.append(f"{seq.name}:{exc.code}")
            else:
                outcome = await self._attempt(k, gi, grasp, seq, q_start, (box_c, box_e),
                                              f"{grasp.kind}:{gi}:{seq.name}", failures)
                if outcome is not None:
                    return outcome
        if self.j.grasp_mode == "top_down":  # the last strategy here: bring it to where the arm works best
            moved = await self._reposition(k, view.center, view.height, chains, (box_c, box_e), failures,
                                           proactive=False)
            if moved is not None:
                return moved
            turned = await try_pitched_turn(self, k, view, (box_c, box_e), failures)  # the pick a box allows
            if turned is not None:
                return turned
            laid = await try_lay_down(self, k, view, (box_c, box_e), failures)  # too tall to turn standing
            if laid is not None:
                return laid
            pushed = await try_push(self, k, view, (box_c, box_e), failures)  # no pick reaches it: turn it on the table
            if pushed is not None:
                return pushed
        self._plan = None
        if self.j.grasp_mode != "top_down":
            self.j.grasp_mode = "top_down"
            self.decide("falling back to top-down grasps", failures=failures[:8])
            return State.PLAN_GRASP
        self.j.grasp_mode = "auto"
        return await self._rescan(k, "no executable grasp")

    async def _reposition(self, k: int, center: np.ndarray, height: float,
                          chains: list[tuple[int, Grasp, TurnPoses]], box: tuple[np.ndarray, np.ndarray],
                          failures: list[str], proactive: bool) -> State | None:
        """Pick the object and set it down, unturned, at the nearest favoured spot it can be scanned at
        (``reposition.py``): ``proactive`` when it drifted off every favoured spot, else as the last resort
        of a view where no turn is executable. The next state, or None when no reposition was executed."""
        rc = self.config.turn.relocation
        done = sum(1 for e in self._regrasps_now(k) if e.get("strategy") == "reposition")
        if not (rc.enabled and rc.reposition) or done >= rc.max_repositions or not chains:
            return None
        spots = favoured_spots(self._workspace_center(), rc)
        off = drift(center, spots)
        if proactive and off <= rc.reposition_drift:
            return None
        shifts = reposition_shifts(center, spots, rc.min_shift)
        self.decide("repositioning: " + ("the object stands off every spot the arm works best at" if proactive
                                         else "no turn is executable where the object stands"),
                    drift=round(off, 3), spots=[np.round(center[:2] + d[:2], 3).tolist() for d in shifts])
        scannable: dict[tuple, bool] = {}
        checks = 0
        for d in shifts:
            if not await self._scannable_spot(center + d, height, scannable):
                continue
            seen: set[tuple[int, str]] = set()
            for gi, grasp, seq in chains:
                base = seq.name.removesuffix("_reverse")  # one turn direction or the other: the same pick
                if (gi, base) in seen or checks >= rc.max_checks:
                    continue
                seen.add((gi, base))
                chain = relocated(without_turn(seq), d)
                checks += 1
                self.j.counters.grasp_checks += 1
                q_start = await self._dry_run(k, chain, center, float(grasp.width), failures)
                if q_start is None:
                    continue
                outcome = await self._attempt(k, gi, grasp, chain, q_start, box, f"{grasp.kind}:{gi}:{chain.name}",
                                              failures)
                if outcome is not None:
                    return outcome
        self.decide("no reposition executable", checks=checks)
        return None

    # ------------------------------------------------------------------------------------- resume a turn
    async def _recover_turn(self) -> None:
        """Settle a turn the previous orchestrator left open, from what the arm reports.

        - at the planned release pose after the object was held: the turn finished, only its record is
          missing; release if still closed and record it (never turn again);
        - elsewhere with the fingers closed on the object: set it down where the hand is, then open (never
          open first: that drops it);
        - then, if it was held, the object may be part-turned: re-scan this view; if it was only about to be
          gripped, the turn is planned again.
        """
        intent = self.j.turn_intent
        k, phase = int(intent["view"]), intent.get("phase")
        opening = float(intent.get("opening", 0.1))
        state = await self.cell.state()
        at_release = released_at(state.T_base_gripper, intent["release_T"])
        closed = float(state.gripper_opening) < opening - 0.005
        self.decide("recovering an interrupted turn", phase=phase, at_release=bool(at_release),
                    gripper_closed=bool(closed), gripper_opening=round(float(state.gripper_opening), 4))
        if phase == "holding" and at_release:
            if closed:
                await self.cell.gripper(opening, self.config.turn.gripper_force)
            self._record_release(k, int(intent["direction"]), intent.get("shift"))
            self.decide("turn had finished before the restart: recorded, not repeated" if int(intent["direction"])
                        else "reposition had finished before the restart: recorded, the view is scanned again",
                        view=self.view)
            return
        if closed:
            if phase == "holding":  # possibly lifted: lower it back onto the table first
                await self.motion.set_down_here(self.config.turn.lift)
            await self.cell.gripper(opening, self.config.turn.gripper_force)
        self.turns.intent(None)
        await self.motion.escape(np.asarray(intent["center"], float), float(intent["height"]))
        self.j.view = k
        if phase == "holding":  # the object may have turned part of the way: this view is no longer true
            self.j.state = State.REGISTER.value  # _rescan's transition to SCAN is from REGISTER
            self._go(await self._rescan(k, "turn interrupted by a restart"))
        else:
            self.j.state = State.PLAN_GRASP.value
        self._persist()

    async def model(self) -> State:
        n = self.config.views
        views = [self.store.load_view(k) for k in range(n)]
        turns = [float(t) for t in self.j.turns_deg[:n]]
        self.incremental.catch_up(n - 1, turns)  # after a resume: any edge not started yet
        reuse = await self.incremental.finished()
        config = with_turn_accuracy(self.incremental.config, self.config.turn_accuracy_deg)  # as reconstruct does
        result = await self.cell.build_model(views, turns, {**config, "reuse_pairs": reuse})
        path = self.store.save_model(result.cloud)
        lateness = model_lateness_s(self.store, path, n - 1, SCANS_PER_VIEW - 1)
        if lateness is not None:
            self.j.model_ready_s_after_last_view = lateness
        self.j.model_path = str(path)
        self.j.model_accepted = bool(result.figures.get("accepted", True))
        self.j.model_why = str(result.figures.get("why", ""))
        accuracy = None
        if self.config.evaluate and self.j.simulated:
            accuracy = await evaluate_against_twin(self.cell, self.store, result.cloud.xyz)
            self.j.accuracy = journal_accuracy(accuracy)
        self.decide("model built" if self.j.model_accepted else "model built, NOT accepted",
                    points=len(result.cloud), accuracy=self.j.accuracy, why=self.j.model_why)
        write_report(self.store, acquisition_report(self.j, self.store, result, turns, self.config.incremental,
                                                    accuracy))
        if self.library is not None:
            inserted = await insert_session_model_async(self.library, self.store.path)
            if inserted.ok:
                self.j.library_entry = inserted.entry
                self.decide("model added to the library", entry=inserted.entry, library=str(self.library))
            else:
                self.decide("could not add the model to the library", error=inserted.error)
        await self._park()
        return State.DONE

"""The orchestrator's Zenoh face.

- ``orchestrator/run`` (``Request``: ``config`` map, ``out`` folder, or ``resume`` folder) → starts one
  acquisition in the background and answers at once with its session folder;
- ``orchestrator/status``: queryable and a stream (published at every step) of state, view, attempts,
  last error, model path and accuracy;
- ``orchestrator/stop``: parks the acquisition in ``stopped`` (resumable) at once and e-stops the arm (one
  attempt, bounded wait); the reply says what the arm answered (``arm``: ``answered``, ``estopped``, ``ms``).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from common import keys
from common.codec import Message
from common.errors import InvalidRequest, ObjscanError
from common.messages import Ok, Request
from common.paths import PathNotAllowed, confine
from common.runtime import COMMAND_BUDGET, QueryContext, Service, run_service, service_arg_parser, settings_from_args
from services.orchestrator.cell import Cell
from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.machine import Acquisition
from services.orchestrator.recording_hook import recorded_acquisition
from services.session_store import SessionStore

STOP_PARK_S = 1.0  # how long a stop reply waits for the cancelled run to park (it does not block it)


class OrchestratorService(Service):
    name = "orchestrator"

    async def setup(self) -> None:
        self.sessions_root = Path(self.settings.options.get("sessions", "sessions")).resolve()
        self.cell = Cell(self.request, self.robot)
        self.current: Acquisition | None = None
        self.task: asyncio.Task[Any] | None = None
        self.last_status: dict[str, Any] = {"state": "idle", "status": "idle"}
        r = self.robot
        self.status_pub = self.publisher(keys.orchestrator(r, "status"))
        self.queryable(keys.orchestrator(r, "run"), self.run_acquisition, budget=COMMAND_BUDGET)
        self.queryable(keys.orchestrator(r, "status"), self.status, budget=COMMAND_BUDGET)
        self.queryable(keys.orchestrator(r, "stop"), self.stop_acquisition, budget=COMMAND_BUDGET, priority=True)

    def _publish(self, status: dict[str, Any]) -> None:
        self.last_status = status
        self.status_pub.put(Ok(info=status))

    async def run_acquisition(self, msg: Message | None, ctx: QueryContext) -> Ok:
        if self.task is not None and not self.task.done():
            raise ObjscanError("an acquisition is already running", code="busy",
                               detail={"session": str(self.current.store.path) if self.current else None})
        params = msg.params if isinstance(msg, Request) else {}
        if not isinstance(params, dict):
            raise InvalidRequest("run parameters must be a map")
        # every path is checked against this orchestrator's roots before anything is created, so a request cannot
        # make the orchestrator write outside the folders it was started with
        library = self._library(params)
        if params.get("resume"):
            path = confine(params["resume"], self.sessions_root, what="resume")
            store = SessionStore.open(path)
            config = AcquisitionConfig()
        else:
            out = params.get("out") or f"session-{int(asyncio.get_running_loop().time())}"
            path = confine(out, self.sessions_root, what="out")
            config = AcquisitionConfig.from_dict(params.get("config", {}))  # validated before the folder exists
            store = SessionStore.create(path)
        store.acquire_lock()  # one orchestrator per session folder; released when the run ends
        try:
            # session recording (docs/recording.md): on unless the run says ``record: false``
            self.current, run = recorded_acquisition(
                lambda cell: Acquisition(cell, store, config, on_status=self._publish, library=library),
                self.request, path, self.session, self.robot, enabled=params.get("record", True) is not False,
                live=bool(params.get("live", False)) or bool(self.settings.options.get("tap", False)))
        except BaseException:
            store.release_lock()
            raise
        self.task = self.spawn(self._locked_run(run, store))
        return Ok(info={"session": str(path), "resumed": self.current.resumed,
                        "status": self.current.j.status})

    @staticmethod
    async def _locked_run(run: Any, store: SessionStore) -> Any:
        try:
            return await run
        finally:
            store.release_lock()

    def _library(self, params: dict[str, Any]) -> Path | None:
        """The model library for this run: the configured one, or none (``library: null``); nothing else."""
        configured = self.settings.options.get("library", "models")
        if "library" not in params:
            return Path(configured).resolve() if configured else None
        if not params["library"]:
            return None
        if not configured:
            raise PathNotAllowed("this orchestrator has no model library configured", detail={"what": "library"})
        return confine(params["library"], configured, what="library", allow_root=True)


    async def status(self, msg: Message | None, ctx: QueryContext) -> Ok:
        return Ok(info=self.current.status() if self.current else self.last_status)

    async def stop_acquisition(self, msg: Message | None, ctx: QueryContext) -> Ok:
        """Stop the acquisition at once and e-stop the arm, and say what the arm answered.

        The acquisition is stopped first (cancelled: it parks in ``stopped``, resumable), then the arm gets
        one e-stop with a bounded wait (``Cell.estop_once``): an unavailable arm never holds the stop in the
        retry loop every other call goes through. The reply carries the arm's answer (or why none came) so
        the one who asked can report it truthfully."""
        running = self.task is not None and not self.task.done()
        if self.current is not None:
            self.current.stop_requested.set()
        if running:
            self.task.cancel()  # type: ignore[union-attr]
        arm = await self.cell.estop_once()
        if running:  # the cancelled run writes its journal and publishes ``stopped``: give it a moment
            await asyncio.wait({self.task}, timeout=STOP_PARK_S)  # type: ignore[arg-type]
        return Ok(info={"stopped": True, "acquisition": self.last_status.get("status"), "arm": arm})

    def health_info(self) -> dict[str, object]:
        s = self.current.status() if self.current else self.last_status
        return {"state": s.get("state"), "view": s.get("view"), "session": s.get("session")}


def main() -> None:
    p = service_arg_parser("objscan orchestrator: the acquisition state machine")
    p.add_argument("--sessions", default="sessions", help="root folder for new sessions (default: %(default)s)")
    p.add_argument("--library", default="models", help="model library folder (default: %(default)s)")
    p.add_argument("--tap", action="store_true",
                   help="publish every run's exchanges on orchestrator/tap, as a run with live: true does "
                        "(the ROS 2 face republishes frames, clouds and the model from it)")
    args = p.parse_args()
    run_service(lambda: OrchestratorService(settings_from_args(args, sessions=args.sessions,
                                                               library=args.library, tap=args.tap)))

"""The orchestrator's side of recording: one ``SessionRecorder`` per run, in one call.

``OrchestratorService.run_acquisition`` does::

    self.current, run = recorded_acquisition(
        lambda cell: Acquisition(cell, store, config, on_status=self._publish), self.request, path,
        self.session, self.robot, enabled=params.get("record", True))
    self.task = self.spawn(run)

The acquisition gets its own ``Cell`` whose requester records every exchange (failures included), the
recorder subscribes to the arm state and status streams, and ``run`` closes the recording when the
acquisition ends, however it ends. A resumed session gets a new part (``session.partN.mcap``); the
earlier files are never touched. If the acquisition cannot even be created (bad journal, ...), the
just-opened, empty part is closed and removed.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

from common import keys
from services.orchestrator.cell import Cell
from services.recording.recorder import RecorderConfig, SessionRecorder, recording_path


def start_recording(session_dir: str | Path, zenoh_session: Any, robot: str,
                    config: RecorderConfig | None = None) -> SessionRecorder:
    """Open the next recording file of ``session_dir`` and subscribe to the cell's state and status streams."""
    recorder = SessionRecorder(recording_path(session_dir), config=config)
    if zenoh_session is not None:
        recorder.subscribe(zenoh_session, [keys.arm(robot, "state"), keys.orchestrator(robot, "status")])
    return recorder


def describe_run(recorder: SessionRecorder | None, acquisition: Any) -> None:
    """The ``session`` metadata record: what is scanned, with which profile, seed and full config."""
    if recorder is None:
        return
    cfg = acquisition.config.to_dict()
    recorder.add_metadata("session", {
        "object": cfg.get("object"), "profile": cfg.get("profile"), "seed": cfg.get("seed"),
        "views": cfg.get("views"), "config": cfg, "session_dir": str(Path(acquisition.store.path).resolve()),
        "robot": acquisition.cell.robot, "resumed": bool(acquisition.resumed), "part": recorder.path.name,
        "started": time.time()})


async def run_recorded(acquisition: Any, recorder: SessionRecorder | None) -> dict[str, Any]:
    """Run the acquisition; close the recording at the end whatever happens (done, failed, stopped)."""
    try:
        return await acquisition.run()
    finally:
        if recorder is not None:
            status = acquisition.j.status
            await asyncio.to_thread(recorder.close, {"status": status, "model": acquisition.j.model_path})


def recorded_acquisition(make_acquisition: Callable[[Cell], Any], send: Any, session_dir: str | Path,
                         zenoh_session: Any, robot: str, *, enabled: bool = True,
                         config: RecorderConfig | None = None,
                         live: bool = False) -> tuple[Any, Coroutine[Any, Any, dict[str, Any]]]:
    """(acquisition, coroutine that runs it and closes its recording): the acquisition's Cell records.

    ``live``: every exchange is also published on the orchestrator's tap key for a live view
    (``services/live/tap.py``), recorded or not.
    """
    if live and zenoh_session is not None:
        from services.live.tap import tapped

        send = tapped(send, zenoh_session, robot)
    recorder = start_recording(session_dir, zenoh_session, robot, config) if enabled else None
    try:
        acquisition = make_acquisition(Cell(recorder.wrap(send) if recorder else send, robot))
    except BaseException:
        if recorder is not None:
            recorder.close({"status": "not started"})
            recorder.path.unlink(missing_ok=True)  # nothing was recorded; keep the part numbers dense
        raise
    describe_run(recorder, acquisition)
    return acquisition, run_recorded(acquisition, recorder)

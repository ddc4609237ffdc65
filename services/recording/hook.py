"""The orchestrator's side of recording: one ``SessionRecorder`` per run, in a few calls.

``OrchestratorService.run_acquisition`` does::

    recorder = start_recording(store.path, self.session, self.robot) if params.get("record", True) else None
    cell = Cell(recorder.wrap(self.request) if recorder else self.request, self.robot)
    acquisition = Acquisition(cell, store, config, ...)
    describe_run(recorder, acquisition)
    task = spawn(run_recorded(acquisition, recorder))

A resumed session gets a new part (``session.partN.mcap``); the earlier files are never touched.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

from common import keys
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
            status = acquisition.j.get("status")
            await asyncio.to_thread(recorder.close, {"status": status, "model": acquisition.j.get("model_path")})

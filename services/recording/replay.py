"""Full replay: the recorded session run again, with the robot half played back and the thinking live.

``replay_session`` starts a private cell on a free loopback port: the Zenoh router, registration,
grasp and orchestrator as in any acquisition, and camera and arm as ``replay_cell`` processes answering
from the recording; no sim. It asks the orchestrator to run the recorded config into ``out_dir``, waits
for the end, and compares the new ``model.ply`` with the recorded model. When the live services decide
as they did in the recording, every camera and arm request matches and the run completes; when they do
not, the replay cell refuses the first differing request (``replay_diverged``) and the report says
which one. The new session folder gets its own recording (``out_dir/session.mcap``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common import keys
from common.api import ModelResult
from common.atomic import atomic_write_bytes
from common.client import request_sync
from common.errors import ObjscanError
from common.launcher import ProcessSpec, ServiceGroup
from common.messages import Health, Ok, Request
from common.session_folder import MODEL_FILE
from services.recording.compare import compare_models
from services.recording.errors import RecordingError
from services.recording.reader import read_recording
from services.recording.recorder import recording_parts

Progress = Callable[[dict[str, Any]], None]


def _recorded_model(rec: Any) -> Any:
    model = None
    for ex in rec.exchanges_on(keys.REGISTRATION_DYNAMIC):
        reply = ex.reply_message()
        if isinstance(reply, ModelResult):
            model = reply.cloud
    return model


def _health(group: ServiceGroup, service: str) -> dict[str, Any]:
    try:
        reply = request_sync(group.session, f"{keys.ROOT}/{service}/*/health", timeout=5.0)
    except ObjscanError as exc:
        return {"error": exc.code}
    return dict(reply.info) if isinstance(reply, Health) else {}


def replay_session(source: str | Path, out_dir: str | Path, *, atol: float = 1e-4, tolerance_mm: float = 0.5,
                   timeout_s: float = 1800.0, progress: Progress | None = None,
                   config_overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Replay ``source`` (a session folder with its recording, or an MCAP file) into ``out_dir``.

    Returns (and writes to ``out_dir/replay.json``): the final orchestrator status, the replay cell's
    figures (requests served, largest deviation, divergence), the comparison of the models and times.
    """
    src = Path(source)
    files = recording_parts(src) if src.is_dir() else [src]
    if not files:
        raise RecordingError(f"{src} has no recording (session.mcap) to replay", detail={"source": str(src)})
    rec = read_recording(src)
    config = {**rec.run_config(), **(config_overrides or {})}
    robot = str(rec.metadata.get("session", {}).get("robot") or keys.DEFAULT_ROBOT)
    out = Path(out_dir).resolve()
    if (out / "journal.json").exists():
        raise RecordingError(f"{out} already holds a session; choose an empty folder", detail={"out": str(out)})
    out.mkdir(parents=True, exist_ok=True)
    cell_args = [a for f in files for a in ("--recording", str(Path(f).resolve()))] + ["--atol", str(atol)]
    specs = [ProcessSpec("services.registration", service="registration"),
             ProcessSpec("services.grasp", service="grasp"),
             ProcessSpec("services.orchestrator", ["--sessions", str(out.parent)], service="orchestrator"),
             ProcessSpec("services.recording.replay_cell", ["--role", "camera", *cell_args], service="camera",
                         name="camera"),
             ProcessSpec("services.recording.replay_cell", ["--role", "arm", *cell_args], service="arm", name="arm")]
    t0 = time.time()
    report: dict[str, Any] = {"source": [str(f) for f in files], "out": str(out), "config": config,
                              "truncated_sources": [str(p) for p in rec.truncated]}
    with ServiceGroup(log_dir=out / "logs", robot=robot) as group:
        group.launch(specs, timeout=180)
        report["startup_s"] = round(time.time() - t0, 2)
        request_sync(group.session, keys.orchestrator(robot, "run"),
                     Request(params={"out": str(out), "config": config}), timeout=30)
        status: dict[str, Any] = {}
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            time.sleep(1.0)
            try:
                reply = request_sync(group.session, keys.orchestrator(robot, "status"), timeout=10)
            except ObjscanError:
                continue
            if isinstance(reply, Ok):
                status = dict(reply.info)
                if progress is not None:
                    progress(status)
                if status.get("status") in ("done", "failed", "stopped"):
                    break
        else:
            status["status"] = "timeout"
        report["status"] = status
        report["camera"] = _health(group, "camera")
        report["arm"] = _health(group, "arm")
    report["seconds"] = round(time.time() - t0, 2)
    recorded = _recorded_model(rec)
    model_path = out / MODEL_FILE
    if recorded is not None and model_path.is_file():
        from services.registration.api import read_ply, write_ply

        tmp = out / ".recorded_model.ply"  # the recorded model as the orchestrator saved it (PLY round trip)
        write_ply(tmp, recorded)
        try:
            report["comparison"] = compare_models(read_ply(tmp), read_ply(model_path), tolerance_mm)
        finally:
            tmp.unlink(missing_ok=True)
    report["model"] = str(model_path) if model_path.is_file() else None
    atomic_write_bytes(out / "replay.json", json.dumps(report, indent=1, default=str).encode())
    return report

"""``objscan replay --only registration``: re-run the registration on a recorded session's frames.

The inputs are exactly what the registration service was sent: from the recording, the last
``StaticRequest`` of every view (a re-scan replaces the earlier attempt) and the ``DynamicRequest``'s
commanded turns and config; from a session folder without a recording, its complete scans,
``session.json``'s turns and the run's config. The steps are the ones the services run, in-process:
static registration per view (``register_view`` with the view's profile), the wire form of its result,
the session folder's PLY round trip the orchestrator makes (``SessionStore.save_view`` / ``load_view``),
then the dynamic stage (``build_model`` with the request's config). A different ``static_profile`` or
``dynamic_config`` compares another method on old scans.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common import keys
from common.api import DynamicRequest, ModelResult, StaticRequest, ViewResult
from common.atomic import atomic_write_bytes
from common.messages import PointCloud, RGBDFrame
from common.pose_accuracy import session_pose_accuracy
from common.session_folder import MODEL_FILE, read_scan, read_session, write_scan
from services.recording.compare import compare_models
from services.recording.errors import RecordingError
from services.recording.reader import read_recording
from services.recording.recorder import recording_parts

Progress = Callable[[str], None]


@dataclass
class RegistrationInputs:
    """What the registration was given in the recorded session, and the model it answered."""

    views: dict[int, list[RGBDFrame]]  # view index -> frames, in scan order
    static_profile: str
    turns_deg: dict[int, float]
    dynamic_config: dict[str, Any]
    recorded_model: PointCloud | None
    source: str
    extra: dict[str, Any] = field(default_factory=dict)
    pose_accuracy: dict[str, Any] = field(default_factory=dict)  # the arm's, as the run sent it ({}: not stated)


def inputs_from_recording(source: str | Path) -> RegistrationInputs:
    rec = read_recording(source)
    views: dict[int, list[RGBDFrame]] = {}
    profile = "default"
    accuracy: dict[str, Any] = {}
    for ex in rec.exchanges_on(keys.REGISTRATION_STATIC):
        req, reply = ex.request_message(), ex.reply_message()
        if isinstance(req, StaticRequest) and isinstance(reply, ViewResult) and req.view >= 0:
            views[req.view] = list(req.frames)  # a re-scan's request comes later and replaces it
            profile = req.profile
            accuracy = dict(req.pose_accuracy)
    if not views:
        raise RecordingError(f"{rec.paths[0]} records no successful static registration", detail={
            "paths": [str(p) for p in rec.paths]})
    turns: dict[int, float] = {}
    dyn_config: dict[str, Any] = {}
    model: PointCloud | None = None
    for ex in rec.exchanges_on(keys.REGISTRATION_DYNAMIC):
        req, reply = ex.request_message(), ex.reply_message()
        if isinstance(req, DynamicRequest):
            turns = {k: float(t) for k, t in enumerate(req.turns_deg)}
            dyn_config = dict(req.config)
        if isinstance(reply, ModelResult):
            model = reply.cloud
    if not turns:  # the run did not get to the model: commanded turns from the config
        cfg = rec.metadata.get("session", {}).get("config", {})
        step = float(cfg.get("turn_deg", 30.0))
        turns = {k: step * k for k in views}
        dyn_config = dict(cfg.get("dynamic_config", {}))
    return RegistrationInputs(views=views, static_profile=profile, turns_deg=turns, dynamic_config=dyn_config,
                              recorded_model=model, source=str(rec.paths[0]),
                              extra={"truncated": [str(p) for p in rec.truncated]}, pose_accuracy=accuracy)


def inputs_from_folder(session_dir: str | Path) -> RegistrationInputs:
    from services.registration.api import read_ply

    info = read_session(Path(session_dir))
    cfg = info.data.get("config", {}) if isinstance(info.data.get("config"), dict) else {}
    views = {int(v["index"]): [read_scan(info.path, int(v["index"]), j) for j in info.scans(int(v["index"]))]
             for v in info.views}
    views = {k: f for k, f in views.items() if f}
    if not views:
        raise RecordingError(f"{session_dir} has no complete scan to register")
    model_path = info.path / MODEL_FILE
    accuracy, stated = session_pose_accuracy(info.data)
    return RegistrationInputs(views=views, static_profile=str(cfg.get("static_profile", "default")),
                              turns_deg={k: info.commanded_turn_deg(k) for k in views},
                              dynamic_config=dict(cfg.get("dynamic_config", {})),
                              recorded_model=read_ply(model_path) if model_path.is_file() else None,
                              source=str(info.path), pose_accuracy=accuracy.to_dict() if stated == "session" else {})


def registration_inputs(source: str | Path) -> RegistrationInputs:
    """From the recording when there is one (exact requests), else from the session folder."""
    p = Path(source)
    if p.is_file() or (p.is_dir() and recording_parts(p)):
        return inputs_from_recording(p)
    return inputs_from_folder(p)


def replay_registration(source: str | Path, out_dir: str | Path, *, static_profile: str | None = None,
                        dynamic_config: dict[str, Any] | None = None, tolerance_mm: float = 0.5,
                        progress: Progress | None = None) -> dict[str, Any]:
    """Register the recorded frames again into ``out_dir`` (a session folder with ``model.ply``).

    Returns (and writes as ``out_dir/replay.json``) the timings, the model path and, when the recording
    holds a model, the comparison with it (``compare_models``).
    """
    from services.registration.api import (
        build_model,
        model_cloud,
        register_scans,
        view_result,
        views_from_results,
    )
    from services.registration.api import dynamic_config as make_dynamic_config  # the parameter has its name
    from services.session_store import SessionStore

    say = progress or (lambda _m: None)
    inputs = registration_inputs(source)
    out = Path(out_dir)
    if (out / MODEL_FILE).exists():
        raise RecordingError(f"{out} already holds a model; choose an empty folder", detail={"out": str(out)})
    store = SessionStore(out)
    profile = static_profile or inputs.static_profile
    dyn = dict(inputs.dynamic_config if dynamic_config is None else dynamic_config)
    order = sorted(inputs.views)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    for k in order:
        t = time.perf_counter()
        frames = inputs.views[k]
        for j, frame in enumerate(frames):
            write_scan(out, k, j, frame)
        result = register_scans(frames, profile, inputs.pose_accuracy)
        store.save_view(view_result(k, result))
        timings[f"static_view_{k:02d}"] = round(time.perf_counter() - t, 3)
        say(f"view {k}: {len(result.object_cloud)} object points in {timings[f'static_view_{k:02d}']:.1f} s")
    turns = [float(inputs.turns_deg.get(k, 0.0)) for k in order]
    store.write_session_info({"static_profile": profile, "dynamic_config": dyn, "replay_of": inputs.source,
                              "pose_accuracy": inputs.pose_accuracy},
                             len(order), turns)
    report: dict[str, Any] = {"source": inputs.source, "static_profile": profile, "dynamic_config": dyn,
                              "views": order, "turns_deg": turns}
    if len(order) >= 2:
        t = time.perf_counter()
        views = [store.load_view(k) for k in order]
        model = build_model(views_from_results(views, turns), make_dynamic_config(dyn))
        cloud = model_cloud(model)
        report["model"] = str(store.save_model(cloud))
        report["model_figures"] = model.to_json()
        timings["dynamic"] = round(time.perf_counter() - t, 3)
        say(f"model: {len(cloud)} points in {timings['dynamic']:.1f} s")
        if inputs.recorded_model is not None:
            from services.registration.api import read_ply

            replayed = read_ply(out / MODEL_FILE)  # compare what is on disk, as the recorded model.ply
            recorded = _as_saved(inputs.recorded_model, out)
            report["comparison"] = compare_models(recorded, replayed, tolerance_mm)
    timings["total"] = round(time.perf_counter() - t0, 3)
    report["timings_s"] = timings
    atomic_write_bytes(out / "replay.json", json.dumps(report, indent=1, default=str).encode())
    return report


def _as_saved(cloud: PointCloud, out: Path) -> PointCloud:
    """The recorded model as the orchestrator saved it (its PLY round trip), for a like-for-like comparison."""
    from services.registration.api import read_ply, write_ply

    tmp = out / ".recorded_model.ply"
    write_ply(tmp, cloud)
    try:
        return read_ply(tmp)
    finally:
        tmp.unlink(missing_ok=True)

"""``import_sequence``: frames -> base frame -> isolated views -> turns -> a session folder.

The session is what ``objscan reconstruct`` reads: one view per frame (``view_KK/scan_0``) with the fixed
camera's pose in the table-based ``base``, and ``session.json`` with the cumulative turns (given or
estimated) and an ``import`` block saying how they were found. A frame that cannot be read (no partner,
unreadable, not aligned) or whose object cannot be isolated (``no_object``, ``empty_depth``) is left out with a
one-line warning and named in the report (``skipped``, ``skipped_count``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ObjscanError
from common.messages import Intrinsics
from common.session_folder import new_folder_refusal, write_scan, write_session
from services.importer.base_frame import BaseFrameConfig, estimate_base_frame
from services.importer.errors import ImportError_, OutNotEmpty
from services.importer.selfcal import FocalSearchConfig, calibrate_focal, scale_intrinsics
from services.importer.sources import MAX_FRAMES, log, read_frames, skip
from services.importer.turn_graph import TurnGraphConfig
from services.importer.turns import DIRECTIONS, graph_searches, pair_searches, plan_turns
from services.registration.api import StaticConfig, TurnSearchConfig, register_view, view_from_static


@dataclass(frozen=True)
class ImportConfig:
    """What the user knows about the sequence; everything else is estimated."""

    turn_step_deg: float | None = None  # None: estimate each turn
    # the given step's stated uncertainty (deg): estimates further off do not move a turn (None: the graph's)
    turn_step_sigma_deg: float | None = None
    direction: str = "unknown"  # "ccw" | "cw" (seen from above) | "unknown": try both
    every: int = 1  # keep one frame in this many (a 30 fps recording of a slow turntable), applied while reading
    max_frames: int = MAX_FRAMES  # frames kept at most (they are held until the turns are found)
    depth_scale: float = 0.001  # m per depth unit (folder sources; a recording carries its own)
    object_name: str = "imported"
    base: BaseFrameConfig = field(default_factory=BaseFrameConfig)
    turn_search: TurnSearchConfig = field(default_factory=TurnSearchConfig)
    focal: FocalSearchConfig = field(default_factory=FocalSearchConfig)  # self-calibration of fx, fy
    graph: TurnGraphConfig = field(default_factory=TurnGraphConfig)  # the view graph and the loop (turn_graph)

    def __post_init__(self) -> None:
        if self.direction not in DIRECTIONS:
            raise ValueError(f"direction must be one of {DIRECTIONS}, got {self.direction!r}")
        if self.turn_step_sigma_deg is not None and not (0 < self.turn_step_sigma_deg < 90):
            raise ValueError(f"turn_step_sigma_deg must be in (0, 90), got {self.turn_step_sigma_deg}")
        if self.turn_step_deg is not None and not (0 < abs(self.turn_step_deg) < 180):
            raise ValueError(f"turn_step_deg must be in (0, 180), got {self.turn_step_deg}")
        if self.every < 1:
            raise ValueError(f"every must be at least 1, got {self.every}")
        if self.max_frames < 3:
            raise ValueError(f"max_frames must be at least 3, got {self.max_frames}")


def import_sequence(source: str | Path, out_dir: str | Path, intrinsics: Intrinsics | None = None,
                    config: ImportConfig | None = None, static: StaticConfig | None = None,
                    progress: Any = None) -> dict[str, Any]:
    """Import ``source`` into the session folder ``out_dir``; returns the import report (also in session.json).

    ``out_dir`` must be absent or an empty folder, like a new scan's (``OutNotEmpty`` otherwise, with nothing
    written): an import into a finished session would replace some of its views and keep its journal, model
    and recording, a session that no longer says what it holds."""
    cfg = config or ImportConfig()
    st = static or StaticConfig()
    say = progress or (lambda info: None)
    t0 = time.perf_counter()
    out = Path(out_dir)
    _check_out(out)
    skipped: list[dict] = []  # frames left out (read: unpaired, unreadable; isolate: no object), one warning each
    frames = read_frames(source, intrinsics, cfg.depth_scale, cfg.every, cfg.max_frames, skipped)
    say({"stage": "read", "frames": len(frames), "seconds": round(time.perf_counter() - t0, 2)})
    base = estimate_base_frame(frames, cfg.base, st)
    say({"stage": "base_frame", "camera_height_m": round(base.camera_height_m, 4),
         "look_down_deg": round(base.look_down_deg, 1)})
    kept, views = [], []
    for f in frames:
        f.T_base_camera = base.T_base_camera.copy()
        try:
            res = register_view([f], st)
        except ObjscanError as exc:
            skip(skipped, f.seq, exc.code, exc.message, stage="isolate")
            continue
        kept.append(f)
        views.append(view_from_static(res, 0.0, index=len(views)))
        say({"stage": "isolate", "frame": f.seq, "of": len(frames), "points": len(res.object_cloud)})
    if skipped:
        log.warning("%d frames skipped in all; %d views imported", len(skipped), len(views))
    if len(views) < 3:
        raise ImportError_(f"fewer than 3 frames show an object standing on the table ({len(skipped)} skipped)",
                           code="too_few_views", detail={"kept": len(views), "skipped": skipped[:10]})
    searches = pair_searches(views, cfg.turn_search)
    closing, further = graph_searches(views, cfg.graph.reach, cfg.turn_search)
    plan = plan_turns(searches, cfg.turn_step_deg, cfg.direction, closing, further, cfg.turn_step_sigma_deg,
                      cfg.graph)
    loop = plan.loop
    assert loop is not None
    say({"stage": "turns", "source": plan.source, "direction": plan.direction, "status": plan.status,
         "total_turn_deg": round(plan.total_turn_deg, 1),
         "median_turn_deg": round(float(np.median(np.abs(plan.pair_yaw_deg))), 2)})
    for pair in loop.unsure_pairs:
        log.warning("turn %d -> %d unsure: %s", pair["from"], pair["to"], pair["why"])
    for why in loop.reasons:
        log.warning("turns unsure: %s", why)
    calib = calibrate_focal(views, base.T_base_camera, searches, plan.total_turn_deg, kept[0].intrinsics,
                            cfg.focal, turns_deg=list(np.diff(plan.cumulative_deg)), loop_closes=loop.loop_closes)
    if calib.applied:  # the written frames carry the corrected intrinsics; the table is fitted again with them
        for f in frames:
            f.intrinsics = scale_intrinsics(f.intrinsics, calib.scale)
        base = estimate_base_frame(frames, cfg.base, st)
        for f in kept:
            f.T_base_camera = base.T_base_camera.copy()
    say({"stage": "focal", **calib.to_json()})
    _check_out(out)  # again: the folder may have been filled while the frames were processed
    out.mkdir(parents=True, exist_ok=True)
    for k, f in enumerate(kept):
        write_scan(out, k, 0, f, extra={"pose_source": "table_plane", "source_frame": int(f.seq)})
    report = {
        "source": str(source),
        "frames": len(frames),
        "views": len(kept),
        "skipped": skipped,
        "skipped_count": len(skipped),
        "base_frame": base.to_json(),
        "turns": plan.to_json(),
        "focal_calibration": calib.to_json(),
        "seconds": round(time.perf_counter() - t0, 3),
    }
    session = {
        "object": cfg.object_name,
        "profile": "imported",
        "camera": "fixed",  # reconstruct: every view differs by a turn on the one table (pair.turn_only)
        "views": [{"index": k, "commanded_turn_deg": round(c, 4), "turn_source": plan.source}
                  for k, c in enumerate(plan.cumulative_deg)],
        "import": report,
    }
    if cfg.turn_step_deg is not None:  # a turntable's step: the model's turns are judged against it
        session["turn_accuracy_deg"] = cfg.turn_step_sigma_deg or cfg.graph.step_sigma_deg
    write_session(out, session)
    return report


def _check_out(out: Path) -> None:
    """Refuse an ``--out`` that is not absent or empty (``OutNotEmpty``), before anything is written."""
    refusal = new_folder_refusal(out)
    if refusal is not None:
        raise OutNotEmpty(f"{out} {refusal}: an import writes a new session, into an absent or empty folder "
                          "(choose another --out)", detail={"path": str(out)})

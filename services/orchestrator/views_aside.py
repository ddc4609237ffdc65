"""Setting an acquisition's views aside when the object's pose changed in a way no turn accounts for (it
toppled, was laid on its side, was pushed round): the views restart at 0, and what was captured before is
kept on disk under another name, never fused with the new views.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from common.session_folder import view_dir
from services.orchestrator.journal import Journal


def set_views_aside(session: Path, j: Journal, last_view: int, suffix: str, *, evidence: bool = True) -> None:
    """Move ``view_KK`` for K = 0..``last_view`` to ``view_KK_{suffix}`` (idempotent: a resume may call it
    again); with ``evidence``, the journal's per-view evidence of those views (re-grasps, limits, failed
    grasps) is kept under ``"K_{suffix}"``, apart from the new views'."""
    for v in range(last_view + 1):
        src = view_dir(session, v)
        dst = src.with_name(f"{src.name}_{suffix}")
        if src.exists() and not dst.exists():
            shutil.move(str(src), str(dst))
    if evidence:
        for table in (j.regrasps, j.limits, j.failed_grasps):
            for v in range(last_view + 1):
                if str(v) in table:
                    table[f"{v}_{suffix}"] = table.pop(str(v))


def restart_views(session: Path, j: Journal, last_view: int, suffix: str, center: list[float], height: float) -> None:
    """Set views 0..``last_view`` and their evidence aside (``set_views_aside``) and restart the views at 0
    around the object's expected ``center`` and ``height``, with a fresh re-scan budget and no turn made."""
    set_views_aside(session, j, last_view, suffix)
    j.update(view=0, turns_deg=[0.0], scan_sets={}, rescans={}, grasp_mode="auto", centers={"-1": list(center)},
             heights={"-1": float(height)}, turn_direction=None, turn_intent=None, holding=False, pending_rescan=None)

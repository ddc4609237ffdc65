"""The model's accuracy against the twin's ground truth: the evaluation a simulated acquisition ends with.

Its own module because it is a measurement, not a step of the acquisition: the state machine only asks for
the figures once the model is built. The pure part (``truth_in_first_view``, ``accuracy_figures``) takes
arrays, so tests call it without a twin; ``evaluate_against_twin`` fetches the truth from the cell.
"""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np

from services.session_store import SessionStore

#: the figures the journal keeps (``accuracy``, shown in the status); the report keeps them all
JOURNAL_FIGURES = ("chamfer_mm", "accuracy_mm", "completeness_mm", "fscore_2mm", "fscore_5mm")
GT_POINTS = 60000


def truth_in_first_view(gt_xyz: np.ndarray, T_base_object_now: np.ndarray,
                        T_base_object_view0: np.ndarray | None) -> np.ndarray:
    """The ground-truth surface posed as the object stood in view 0 (the model's frame). The twin gives the
    surface where the object stands now; without the view-0 pose it is returned as it is."""
    xyz = np.asarray(gt_xyz, float)
    if T_base_object_view0 is None:
        return xyz
    T_now = np.asarray(T_base_object_now, float)
    T0 = np.asarray(T_base_object_view0, float)
    return (xyz - T_now[:3, 3]) @ T_now[:3, :3] @ T0[:3, :3].T + T0[:3, 3]


def accuracy_figures(model_xyz: np.ndarray, gt_xyz: np.ndarray, posed_from_truth: bool) -> dict[str, Any]:
    """Chamfer/F-score of the model against the posed ground truth, ICP-aligned from the true pose (never
    from scratch, where a nearly square carton can lock 90 degrees off), and the raw figures as ``unaligned``.
    CPU: the caller runs it in a thread."""
    from services.registration.api import evaluate_model  # on first use: it loads Open3D

    model = np.asarray(model_xyz, float)
    aligned = evaluate_model(model, gt_xyz, align=True, init_T=np.eye(4))
    raw = evaluate_model(model, gt_xyz, align=False)
    out = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in aligned.items()}
    out["unaligned"] = {k: v for k, v in raw.items() if isinstance(v, float)}
    out["gt_posed_from_truth"] = posed_from_truth
    return out


def journal_accuracy(figures: dict[str, Any]) -> dict[str, float]:
    """The headline figures the journal keeps of a full evaluation."""
    return {k: figures[k] for k in JOURNAL_FIGURES if k in figures}


async def evaluate_against_twin(cell: Any, store: SessionStore, model_xyz: np.ndarray) -> dict[str, Any]:
    """Chamfer/F-score against the twin's ground-truth surface, posed as the object stood in view 0."""
    T0 = store.load_scan(0, 0).meta.get("T_base_object_true")
    gt = await cell.sim("gt_points", n=GT_POINTS)
    xyz = truth_in_first_view(gt["xyz"], gt["T_base_object"], None if T0 is None else np.asarray(T0, float))
    return await asyncio.to_thread(accuracy_figures, model_xyz, xyz, T0 is not None)

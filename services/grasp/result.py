"""What the planner returns: ranked grasps with their metrics and poses, and why the others failed."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.messages import Grasp, Pose
from services.grasp.boxes import OrientedBox

REASONS = (
    "too_short_for_frontal",
    "side_not_seen",
    "too_few_points",
    "too_wide",
    "grasp_line_not_horizontal",
    "not_antipodal",
    "rank_below_threshold",
    "collides_with_table",
    "collides_with_object",
)
"""Every rejection reason the planner reports, roughly in pipeline order."""


@dataclass
class PlannedGrasp:
    """One surviving grasp.

    ``contacts`` (2, 3) in base, ordered so the gripper's y runs from contacts[1] to contacts[0];
    ``poses`` maps names (grasp, grasp_plus15, ..., pregrasp..., turn...) to 4x4 T_base_gripper, best
    first within each group; ``metrics`` holds every ranking term (d, c, cosβ, cosα, r1, r2, rank).
    """

    kind: str  # "frontal" | "top_down"
    axis: str  # region axis the pair came from: "y" | "z"
    contacts: np.ndarray
    contact_normals: np.ndarray
    width: float
    rank: float
    metrics: dict[str, float]
    poses: dict[str, np.ndarray]
    collision_boxes: dict[str, OrientedBox] = field(default_factory=dict)
    """The hand boxes the collision filter checked (pads, and the palm for frontal grasps)."""

    @property
    def T_base_gripper(self) -> np.ndarray:
        return self.poses["grasp"]

    def to_message(self, frame: str = "base") -> Grasp:
        """The wire form: poses as Pose messages (position + quaternion x, y, z, w)."""
        return Grasp(
            kind=self.kind,
            contacts=np.asarray(self.contacts, dtype=np.float64),
            width=float(self.width),
            rank=float(self.rank),
            metrics={"axis": self.axis, **{k: float(v) for k, v in self.metrics.items()}},
            poses={name: Pose.from_matrix(T, frame=frame) for name, T in self.poses.items()},
        )


@dataclass
class Rejections:
    """Counts per reason and up to ``max_examples`` examples (JSON-able dicts) per reason.

    Pair-level reasons (too_wide, grasp_line_not_horizontal, not_antipodal, rank_below_threshold) count
    contact pairs; the others count grasps or whole attempts.
    """

    max_examples: int = 3
    counts: dict[str, int] = field(default_factory=dict)
    examples: dict[str, list[dict[str, Any]]] = field(default_factory=dict)

    def add(self, reason: str, count: int = 1, example: dict[str, Any] | None = None) -> None:
        if reason not in REASONS:
            raise ValueError(f"unknown rejection reason {reason!r}")
        self.counts[reason] = self.counts.get(reason, 0) + int(count)
        if example is not None:
            bucket = self.examples.setdefault(reason, [])
            if len(bucket) < self.max_examples:
                bucket.append(example)

    def __contains__(self, reason: str) -> bool:
        return reason in self.counts

    def as_dict(self) -> dict[str, Any]:
        return {"counts": dict(self.counts), "examples": _jsonable(self.examples)}


@dataclass
class GraspPlan:
    """Result of :func:`services.grasp.planner.plan_grasps`.

    ``grasps`` best first (by rank, frontal before top-down when both were planned); ``rejections``
    explains every candidate that did not make it; ``attempted`` lists the variants that ran.
    """

    grasps: list[PlannedGrasp]
    rejections: Rejections
    attempted: list[str]
    object_center: np.ndarray
    center_slices: int
    main_axis: np.ndarray
    timings_ms: dict[str, float] = field(default_factory=dict)
    completion: dict[str, Any] = field(default_factory=dict)
    """What the planner inferred: per horizontal box axis, the face points seen at each end and whether
    a hidden side face was mirrored in (services/grasp/completion.py); under ``revolved``, when nothing
    was found on that, the vertical axis an upright round object's unseen arc was filled about
    (services/grasp/revolve.py)."""

    def __bool__(self) -> bool:
        return bool(self.grasps)

    def explain(self) -> str:
        """One line for people: what was found, or why nothing was."""
        tried = "+".join(self.attempted) or "nothing"
        completed = self.completion.get("completed_axes") or []
        note = f" (hidden side {'+'.join(completed)} mirrored from the seen one)" if completed else ""
        if self.completion.get("revolved"):
            note += " (unseen arc filled about the round object's vertical axis)"
        if self.grasps:
            kinds = ", ".join(f"{g.kind}/{g.axis} rank {g.rank:.2f}" for g in self.grasps)
            return f"{len(self.grasps)} grasp(s) from {tried}: {kinds}{note}"
        reasons = ", ".join(f"{k} x{v}" for k, v in self.rejections.counts.items()) or "no candidates"
        return f"no grasp from {tried}: {reasons}{note}"

    def to_messages(self, frame: str = "base") -> list[Grasp]:
        return [g.to_message(frame) for g in self.grasps]

    def summary(self) -> dict[str, Any]:
        """JSON-able digest for logs and replies."""
        return _jsonable({
            "n_grasps": len(self.grasps),
            "attempted": self.attempted,
            "grasps": [{"kind": g.kind, "axis": g.axis, "rank": g.rank, "width": g.width,
                        "contacts": g.contacts, "metrics": g.metrics} for g in self.grasps],
            "rejections": self.rejections.as_dict(),
            "object_center": self.object_center,
            "center_slices": self.center_slices,
            "timings_ms": self.timings_ms,
            "completion": self.completion,
            "explain": self.explain(),
        })


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj

"""Request and reply messages of the services' queryables.

They live in ``common`` because both ends must decode them: the orchestrator, the CLI and the tests
import the same classes as the service that answers. Each class documents the key it goes with.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.codec import Message, array_field
from common.errors import WireError
from common.messages import Grasp, Plane, PointCloud, RGBDFrame
from common.pose_accuracy import PoseAccuracy, PoseAccuracyError


@dataclass(kw_only=True)
class CaptureRequest(Message):
    """``objscan/{robot}/camera/capture``: one RGB-D frame. ``0`` sizes mean the backend's default."""

    width: int = 0
    height: int = 0


@dataclass(kw_only=True)
class MoveRequest(Message):
    """``objscan/{robot}/arm/move``: a motion; the reply comes when it has finished or failed.

    ``kind``: ``joints`` (``q``), ``pose`` (joint-space motion to ``target``), ``linear`` (straight
    Cartesian line to ``target``) or ``home``. ``target`` is ``T_base_<frame>`` with frame ``gripper`` or
    ``camera``. ``free_roll`` lets the gripper turn about its approach axis when the exact pose is out of
    reach. On a ``dry_run`` ``pose``/``linear`` move, ``q`` is the configuration to plan from (so a chain of
    motions can be checked before any of them runs); the reply then says where the motion would end. A real
    ``pose``/``linear`` move with ``q`` is refused: it always starts where the arm is. ``check_opening``
    (dry runs) checks the motion with the fingers at that opening instead of the current one.
    """

    kind: str = "pose"
    q: np.ndarray | None = array_field("<f8", (None,), optional=True)
    target: np.ndarray | None = array_field("<f8", (4, 4), optional=True)
    frame: str = "gripper"
    speed_scale: float = 0.5
    free_roll: bool = False
    allow_object_contact: bool = False  # the pads may touch the object box (final grasp approach)
    dry_run: bool = False  # plan and check only: reachability without motion
    # dry runs only: the finger opening (m) the collision check assumes, e.g. closed on the object for the
    # held moves of a pick-turn-place checked before the gripper closes; negative: the fingers' current one
    check_opening: float = -1.0

    def validate(self) -> None:
        if self.kind not in ("joints", "pose", "linear", "home"):
            raise WireError(f"unknown move kind {self.kind!r}", code="bad_value")
        if self.kind == "joints" and self.q is None:
            raise WireError("a joints move needs q", code="missing_field")
        if self.kind in ("pose", "linear") and self.target is None:
            raise WireError(f"a {self.kind} move needs target", code="missing_field")
        if self.frame not in ("gripper", "camera"):
            raise WireError(f"unknown frame {self.frame!r}", code="bad_value")
        if not 0.0 < self.speed_scale <= 1.0:
            raise WireError("speed_scale must be in (0, 1]", code="bad_value")


@dataclass(kw_only=True)
class MoveResult(Message):
    """Where the arm ended: joints, TCP and camera poses, and how long the motion took."""

    q: np.ndarray = array_field("<f8", (None,))
    T_base_gripper: np.ndarray = array_field("<f8", (4, 4))
    T_base_camera: np.ndarray = array_field("<f8", (4, 4))
    duration_s: float = 0.0
    info: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class GripperRequest(Message):
    """``objscan/{robot}/arm/gripper``: open to ``opening`` metres (0 = close) with at most ``force`` N."""

    opening: float = 0.0
    force: float = 20.0


@dataclass(kw_only=True)
class GripperResult(Message):
    """Measured opening after the command, and whether something is held between the pads."""

    opening: float = 0.0
    holding: bool = False
    reason: str = ""


@dataclass(kw_only=True)
class SceneRequest(Message):
    """``objscan/{robot}/arm/scene``: the box around the object the collision checker must avoid.

    ``extent`` zero clears it (e.g. while the object is held)."""

    center: np.ndarray = array_field("<f8", (3,))
    extent: np.ndarray = array_field("<f8", (3,))
    yaw: float = 0.0


@dataclass(kw_only=True)
class StaticRequest(Message):
    """``objscan/registration/static``: the scans of one view → the isolated object of that view."""

    frames: list[RGBDFrame] = field(default_factory=list)
    profile: str = "default"
    view: int = 0
    # the arm's camera pose accuracy ({"position_sigma_mm", "orientation_sigma_deg"}, common/pose_accuracy.py):
    # a scan correction beyond what it explains is not fused; empty: the registration's conservative default
    pose_accuracy: dict = field(default_factory=dict)

    def validate(self) -> None:
        if not self.frames:
            raise WireError("a static registration needs at least one frame", code="empty")
        if self.pose_accuracy:
            try:
                PoseAccuracy.from_dict(self.pose_accuracy)
            except PoseAccuracyError as exc:
                raise WireError(exc.message, code="bad_value", detail=exc.detail) from exc


@dataclass(kw_only=True)
class ViewResult(Message):
    """One registered view: object cloud in ``base``, table plane, object centre and height, scan poses."""

    view: int = 0
    cloud: PointCloud
    table: Plane
    center: np.ndarray = array_field("<f8", (3,))
    height: float = 0.0
    scan_poses: np.ndarray = array_field("<f8", (None, 4, 4))
    figures: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class GraspRequest(Message):
    """``objscan/grasp/plan``: grasps for an isolated object cloud (with normals) on a table."""

    cloud: PointCloud
    table: Plane
    mode: str = "auto"  # "auto" (frontal, top-down when none) | "frontal" | "top_down" | "both"

    def validate(self) -> None:
        if self.mode not in ("auto", "frontal", "top_down", "both"):
            raise WireError(f"unknown grasp mode {self.mode!r}", code="bad_value")


@dataclass(kw_only=True)
class GraspPlanReply(Message):
    """Ranked grasps (best first) and, when none survive, why."""

    grasps: list[Grasp] = field(default_factory=list)
    rejections: dict = field(default_factory=dict)
    explanation: str = ""
    seconds: float = 0.0


@dataclass(kw_only=True)
class DynamicRequest(Message):
    """``objscan/registration/dynamic``: the registered views (in order) → one model."""

    views: list[ViewResult] = field(default_factory=list)
    turns_deg: list[float] = field(default_factory=list)
    config: dict = field(default_factory=dict)

    def validate(self) -> None:
        if len(self.views) < 2:
            raise WireError("a model needs at least two views", code="empty")
        if len(self.turns_deg) != len(self.views):
            raise WireError("one commanded turn per view is required", code="bad_shape")


@dataclass(kw_only=True)
class EdgeRequest(Message):
    """``objscan/registration/edge``: the views one edge of the incremental model needs → its pair results.

    The orchestrator sends views; the registration side builds the edge's jobs (``source`` onto ``source -
    1``) in ``configurations``, fingerprints them, runs those whose fingerprint is not in ``known`` (already
    stored by the session) and answers an ``EdgeReply``. ``background``: speculative work, run at the
    workers' lowest CPU priority."""

    source: int
    views: list[ViewResult] = field(default_factory=list)
    turns_deg: list[float] = field(default_factory=list)
    config: dict = field(default_factory=dict)
    configurations: list[str] = field(default_factory=list)
    known: list[str] = field(default_factory=list)
    background: bool = False

    def validate(self) -> None:
        if self.source < 1:
            raise WireError("an edge's source view is 1 or later", code="bad_value")
        if len(self.turns_deg) <= self.source:
            raise WireError("one commanded turn per view up to the source is required", code="bad_shape")


@dataclass(kw_only=True)
class EdgeReply(Message):
    """The pair results of an ``EdgeRequest``: one record per job run (``pair_record``: the result with the
    fingerprint of the job it answers) and that job's configuration, in the same order; empty when the
    edge's jobs cannot be known yet or every one was ``known``."""

    records: list[dict] = field(default_factory=list)
    configurations: list[str] = field(default_factory=list)


@dataclass(kw_only=True)
class ModelResult(Message):
    """The model cloud (``base`` of view 0) and its figures: edges, loop closure, configuration chosen."""

    cloud: PointCloud
    figures: dict = field(default_factory=dict)

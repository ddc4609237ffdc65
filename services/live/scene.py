"""What there is to see, from the messages a scan already exchanges: one interpreter for every viewer.

The orchestrator's requests and replies (the recording hook's exchanges, live over the tap or read back
from a recording) and the cell's streams (arm joint state, orchestrator status) become a few plain
events. The Rerun and Foxglove sinks draw these events; neither looks at wire messages itself, so both
show the same scene, live or replayed.

- ``CameraFrame``: a captured RGB-D frame with its intrinsics and the camera pose the robot believed;
- ``ArmState``: joint names and positions (thinned to ``state_rate_hz`` from the 50 Hz stream);
- ``ViewCloud``: the isolated object cloud of a view (``view = -1``: the locate step);
- ``GraspCandidates``: the ranked grasps planned for a view (gripper poses in ``base``);
- ``ChosenGrasp``: the grasp the arm closed on (the last gripper-frame move before a close);
- ``ModelPreview``: the growing model while views come in: every registered view placed by undoing its
  commanded turn about the table normal through the object centre (the dynamic registration's own
  ``prerotation``, its starting point), so it is as good as the turns were; ``Model`` replaces it;
- ``Model``: the model cloud when the dynamic registration returns it;
- ``Status``: the orchestrator's status (state, view, views done).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.api import GraspPlanReply, GripperRequest, ModelResult, MoveRequest, MoveResult, ViewResult
from common.messages import Error, JointState, Ok, PointCloud, RGBDFrame
from services.arm.robot import JOINT_NAMES

CLOSE_BELOW_M = 0.005  # a gripper command below this opening is a close: the grasp is chosen


@dataclass
class CameraFrame:
    t: float
    frame: RGBDFrame


@dataclass
class ArmState:
    t: float
    names: list[str]
    q: np.ndarray
    gripper_opening: float | None = None


@dataclass
class ViewCloud:
    t: float
    view: int
    cloud: PointCloud


@dataclass
class GraspCandidates:
    t: float
    view: int
    poses: list[np.ndarray]  # T_base_gripper of each grasp, best first
    kinds: list[str]


@dataclass
class ChosenGrasp:
    t: float
    view: int
    pose: np.ndarray  # T_base_gripper


@dataclass
class Model:
    t: float
    cloud: PointCloud
    figures: dict[str, Any] = field(default_factory=dict)


@dataclass
class ModelPreview:
    t: float
    views: list[int]
    xyz: np.ndarray  # (N, 3) float32 in view 0's base
    rgb: np.ndarray  # (N, 3) uint8


@dataclass
class Status:
    t: float
    info: dict[str, Any]


Event = CameraFrame | ArmState | ViewCloud | GraspCandidates | ChosenGrasp | ModelPreview | Model | Status

PREVIEW_POINTS_PER_VIEW = 8000


@dataclass
class _Placed:
    """What ``prerotation`` reads of a view: its object centre and its cumulative commanded turn."""

    center: np.ndarray
    commanded_turn_deg: float


def preview(views: dict[int, ViewResult], turns_deg: list[float]) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Views with a known turn, stacked in view 0's frame by undoing their turns (subsampled per view)."""
    from services.registration.api import prerotation

    ks = sorted(k for k in views if 0 <= k < len(turns_deg))
    if not ks or 0 not in views:
        return [], np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)
    axis = np.asarray(views[0].table.normal, dtype=np.float64)
    ref = np.asarray(views[0].center, dtype=np.float64)
    xyzs, rgbs = [], []
    for k in ks:
        v = views[k]
        xyz = np.asarray(v.cloud.xyz, dtype=np.float64)
        rgb = (np.asarray(v.cloud.rgb, dtype=np.uint8) if v.cloud.rgb is not None
               else np.full((len(xyz), 3), 170, np.uint8))
        step = max(1, len(xyz) // PREVIEW_POINTS_PER_VIEW)
        T = prerotation(_Placed(np.asarray(v.center, dtype=np.float64), float(turns_deg[k])), ref, axis)
        xyzs.append((xyz[::step] @ T[:3, :3].T + T[:3, 3]).astype(np.float32))
        rgbs.append(rgb[::step])
    return ks, np.vstack(xyzs), np.vstack(rgbs)


class SceneInterpreter:
    """Turns exchanges and stream samples into events; keeps the little state that needs (view, last move)."""

    def __init__(self, state_rate_hz: float = 10.0):
        self.view = -1
        self.state_period = 1.0 / state_rate_hz if state_rate_hz > 0 else 0.0
        self._last_state_t = -np.inf
        self._grasp_target: np.ndarray | None = None
        self._views: dict[int, ViewResult] = {}
        self._turns: list[float] = []

    def exchange(self, t: float, key: str, request: Any, reply: Any) -> list[Event]:
        """Events from one request and its reply (an ``Error`` reply shows nothing)."""
        if isinstance(reply, Error):
            return []
        out: list[Event] = []
        if (isinstance(request, MoveRequest) and not request.dry_run and request.target is not None
                and request.frame == "gripper"):
            self._grasp_target = np.asarray(request.target, dtype=np.float64)
        if isinstance(request, GripperRequest) and request.opening < CLOSE_BELOW_M and self._grasp_target is not None:
            out.append(ChosenGrasp(t, self.view, self._grasp_target))
            self._grasp_target = None
        if isinstance(reply, RGBDFrame):
            out.append(CameraFrame(t, reply))
        elif isinstance(reply, MoveResult) and not (isinstance(request, MoveRequest) and request.dry_run):
            q = np.asarray(reply.q, dtype=np.float64)
            out.append(ArmState(t, list(JOINT_NAMES[: len(q)]), q))
        elif isinstance(reply, ViewResult):
            self.view = int(reply.view)
            out.append(ViewCloud(t, int(reply.view), reply.cloud))
            if reply.view >= 0:
                self._views[int(reply.view)] = reply
                out += self._preview(t)
        elif isinstance(reply, GraspPlanReply) and reply.grasps:
            named = [g for g in reply.grasps if "grasp" in g.poses]
            poses = [np.asarray(g.poses["grasp"].matrix(), dtype=np.float64) for g in named]
            kinds = [g.kind for g in named]
            if poses:
                out.append(GraspCandidates(t, self.view, poses, kinds))
        elif isinstance(reply, ModelResult):
            out.append(Model(t, reply.cloud, dict(reply.figures)))
        return out

    def sample(self, t: float, msg: Any) -> list[Event]:
        """Events from a stream sample: joint state (thinned) or orchestrator status."""
        if isinstance(msg, JointState):
            if t - self._last_state_t < self.state_period:
                return []
            self._last_state_t = t
            return [ArmState(t, list(msg.names), np.asarray(msg.position, dtype=np.float64),
                             float(msg.gripper_opening))]
        if isinstance(msg, Ok) and "state" in msg.info:
            out: list[Event] = [Status(t, dict(msg.info))]
            turns = msg.info.get("turns_deg")
            if isinstance(turns, list) and len(turns) > len(self._turns):
                known = {k for k in self._views if k < len(self._turns)}
                self._turns = [float(x) for x in turns]
                if {k for k in self._views if k < len(self._turns)} != known:
                    out += self._preview(t)  # a view that arrived before its turn was known joins now
            return out
        return []

    def _preview(self, t: float) -> list[Event]:
        ks, xyz, rgb = preview(self._views, self._turns)
        return [ModelPreview(t, ks, xyz, rgb)] if ks else []

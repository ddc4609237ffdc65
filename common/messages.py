"""The wire messages every service speaks.

Each is a plain dataclass; the codec (``common.codec``) derives the wire form and the validation from
the field types and array specs. Arrays stay numpy arrays end to end. A service that needs a new request
or reply type adds it here (or in its own module, subclassing ``Message``) so every peer can decode it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.codec import Message, array_field
from common.errors import WireError
from common.geometry import as_rigid_transform, matrix_to_pose, pose_to_matrix


@dataclass(kw_only=True)
class Intrinsics(Message):
    """Pinhole intrinsics of the color image (depth is aligned to color)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def validate(self) -> None:
        if self.width <= 0 or self.height <= 0 or self.fx <= 0 or self.fy <= 0:
            raise WireError("intrinsics must be positive", code="bad_value",
                            detail={"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy})

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def as_dict(self) -> dict[str, float]:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Intrinsics:
        return cls(width=int(d["width"]), height=int(d["height"]), fx=float(d["fx"]), fy=float(d["fy"]),
                   cx=float(d["cx"]), cy=float(d["cy"]))


D435_COLOR_FOCAL_PX = 615.0
"""Typical focal length (px) of a D435 colour stream at 480 rows (640x480 and 848x480 alike)."""

D435_COLOR_SIZES = ((640, 480), (848, 480))
"""The D435 colour modes the camera's sim backend and the twin's render key accept."""


def d435_intrinsics(width: int = 640, height: int = 480) -> Intrinsics:
    """The D435 colour camera model, the one definition of it (twin, camera backends, default frame).

    A real D435 reports its own factory calibration (the realsense backend uses that); these are the typical
    values: fx = fy = 615 px at 480 rows, principal point at the image centre. Other sizes (tests render
    small images) scale the focal length with the height. Raises ``bad_value`` for a non-positive size.
    """
    f = D435_COLOR_FOCAL_PX * height / 480.0
    K = Intrinsics(width=int(width), height=int(height), fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)
    K.validate()
    return K


@dataclass(kw_only=True)
class RGBDFrame(Message):
    """One aligned RGB-D capture with the camera pose in ``base`` as the robot believes it.

    ``T_base_camera_true`` is filled only by the simulator: ground truth, for evaluation only, never
    read by the pipeline.
    """

    color: np.ndarray = array_field("u1", (None, None, 3))
    depth: np.ndarray = array_field("<u2", (None, None))
    depth_scale: float = 0.001
    intrinsics: Intrinsics = field(default_factory=d435_intrinsics)
    T_base_camera: np.ndarray = array_field("<f8", (4, 4))
    stamp: float = 0.0
    seq: int = 0
    T_base_camera_true: np.ndarray | None = array_field("<f8", (4, 4), optional=True)
    meta: dict = field(default_factory=dict)

    def validate(self) -> None:
        h, w = self.depth.shape
        if self.color.shape[:2] != (h, w):
            raise WireError("color and depth sizes differ", code="bad_shape",
                            detail={"color": list(self.color.shape), "depth": list(self.depth.shape)})
        if (w, h) != (self.intrinsics.width, self.intrinsics.height):
            raise WireError("image size differs from intrinsics", code="bad_shape",
                            detail={"image": [w, h], "intrinsics": [self.intrinsics.width, self.intrinsics.height]})
        if self.depth_scale <= 0:
            raise WireError("depth_scale must be positive", code="bad_value")


@dataclass(kw_only=True)
class PointCloud(Message):
    """Points in ``frame`` (metres), optional 8-bit colors and unit normals, one row per point."""

    xyz: np.ndarray = array_field("<f4", (None, 3))
    rgb: np.ndarray | None = array_field("u1", (None, 3), optional=True)
    normals: np.ndarray | None = array_field("<f4", (None, 3), optional=True)
    frame: str = "base"

    def validate(self) -> None:
        n = self.xyz.shape[0]
        for name in ("rgb", "normals"):
            arr = getattr(self, name)
            if arr is not None and arr.shape[0] != n:
                raise WireError(f"{name} has {arr.shape[0]} rows, xyz has {n}", code="bad_shape",
                                detail={"field": name})

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


@dataclass(kw_only=True)
class Pose(Message):
    """Position (m) and unit quaternion (x, y, z, w) of ``child`` in ``frame``."""

    position: np.ndarray = array_field("<f8", (3,))
    orientation: np.ndarray = array_field("<f8", (4,))
    frame: str = "base"

    def validate(self) -> None:
        norm = float(np.linalg.norm(self.orientation))
        if abs(norm - 1.0) > 1e-3:
            raise WireError("orientation is not a unit quaternion", code="bad_value", detail={"norm": norm})

    def matrix(self) -> np.ndarray:
        return pose_to_matrix(self.position, self.orientation)

    @classmethod
    def from_matrix(cls, T: np.ndarray, frame: str = "base") -> Pose:
        p, q = matrix_to_pose(T)
        return cls(position=p, orientation=q, frame=frame)


@dataclass(kw_only=True)
class Transform(Message):
    """``matrix`` = T_parent_child: maps points in ``child`` into ``parent``."""

    matrix: np.ndarray = array_field("<f8", (4, 4))
    parent: str = "base"
    child: str = ""

    def validate(self) -> None:
        as_rigid_transform(self.matrix, "matrix", WireError)


@dataclass(kw_only=True)
class JointState(Message):
    """Joint positions (rad, or m for the gripper), velocities, efforts; TCP and camera poses in base."""

    names: list[str] = field(default_factory=list)
    position: np.ndarray = array_field("<f8", (None,))
    velocity: np.ndarray | None = array_field("<f8", (None,), optional=True)
    effort: np.ndarray | None = array_field("<f8", (None,), optional=True)
    stamp: float = 0.0
    T_base_gripper: np.ndarray | None = array_field("<f8", (4, 4), optional=True)
    T_base_camera: np.ndarray | None = array_field("<f8", (4, 4), optional=True)
    gripper_opening: float = 0.0
    moving: bool = False
    # a real arm's safety state: "" / "held" (e-stop latched, every servo held) / "failed" (the hold did not
    # reach every servo), and what ended the last move or the e-stop's failure (code, message, servo named)
    estop: str = ""
    fault: dict = field(default_factory=dict)

    def validate(self) -> None:
        if len(self.names) != self.position.shape[0]:
            raise WireError("names and position lengths differ", code="bad_shape")


@dataclass(kw_only=True)
class Plane(Message):
    """A plane ``normal . p + offset = 0`` with a unit normal (pointing up for the table) and a centre."""

    normal: np.ndarray = array_field("<f8", (3,))
    offset: float = 0.0
    center: np.ndarray = array_field("<f8", (3,))
    frame: str = "base"

    def validate(self) -> None:
        if abs(float(np.linalg.norm(self.normal)) - 1.0) > 1e-3:
            raise WireError("plane normal is not unit length", code="bad_value")

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points, dtype=np.float64) @ self.normal + self.offset


@dataclass(kw_only=True)
class Grasp(Message):
    """One ranked grasp: contacts, width, the four ranking terms, and its named poses in ``base``.

    ``poses`` maps names (``grasp``, ``grasp_plus15``, ``grasp_minus15``, ``pregrasp``, ...,
    ``turn``...) to gripper poses, best first within each group.
    """

    kind: str = "frontal"  # "frontal" | "top_down"
    contacts: np.ndarray = array_field("<f8", (2, 3))
    width: float = 0.0
    rank: float = 0.0
    metrics: dict = field(default_factory=dict)
    poses: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class Error(Message):
    """A typed failure reply. ``code`` is stable; ``message`` is for people; ``detail`` for specifics."""

    code: str = "error"
    message: str = ""
    detail: dict = field(default_factory=dict)
    service: str = ""


@dataclass(kw_only=True)
class Ok(Message):
    """A reply that carries only figures (or nothing), e.g. for a move that finished."""

    info: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class Health(Message):
    """What a service says about itself when asked: alive, busy with what, since when."""

    service: str = ""
    instance: str = ""
    status: str = "ok"
    busy: int = 0
    uptime_s: float = 0.0
    info: dict = field(default_factory=dict)


@dataclass(kw_only=True)
class Request(Message):
    """A generic request: named parameters (numbers, strings, nested messages, arrays)."""

    params: dict = field(default_factory=dict)

"""Foxglove's own message schemas (protobuf, from ``foxglove-sdk``) for what a person wants to *see*.

The raw channels of a recording keep the exact msgpack payloads (for replay); these derived channels
let Foxglove open the same file without plugins: colour and depth images with their calibration, a
transform tree ``base → gripper → camera``, camera and arm target poses, the object cloud of every
view, the grasps planned and the final model. Each function turns one objscan message into
``[(topic, schema_name, protobuf_bytes)]``; the recorder registers schemas and channels on first use.

``foxglove-sdk`` is optional: without it ``available()`` is False and the recorder writes only the raw
channels (and says so in the file's metadata).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from common.api import GraspPlanReply, ModelResult, MoveRequest, MoveResult, ViewResult
from common.geometry import invert, matrix_to_quat_xyzw
from common.messages import JointState, PointCloud, RGBDFrame

try:  # optional: the raw channels do not need it
    import foxglove.messages as fm
except ImportError:  # pragma: no cover - exercised only where foxglove-sdk is absent
    fm = None

Visual = tuple[str, str, bytes]  # topic, schema name, encoded protobuf
BASE, GRIPPER, CAMERA = "base", "gripper", "camera"
JPEG_QUALITY = 92


def available() -> bool:
    return fm is not None


def schema(name: str) -> tuple[str, bytes]:
    """(encoding, data) of a Foxglove schema by name, e.g. ``foxglove.RawImage`` → ("protobuf", FileDescriptorSet)."""
    cls = getattr(fm, name.split(".", 1)[1])
    s = cls.get_schema()
    return s.encoding, bytes(s.data)


def stamp(t: float) -> Any:
    return fm.Timestamp.from_epoch_secs(float(t))


def _vq(T: np.ndarray) -> tuple[Any, Any]:
    T = np.asarray(T, dtype=np.float64)
    q = matrix_to_quat_xyzw(T[:3, :3])
    return (fm.Vector3(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
            fm.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def pose_msg(T: np.ndarray) -> Any:
    v, q = _vq(T)
    return fm.Pose(position=v, orientation=q)


def frame_transform(t: float, parent: str, child: str, T: np.ndarray) -> Any:
    v, q = _vq(T)
    return fm.FrameTransform(timestamp=stamp(t), parent_frame_id=parent, child_frame_id=child,
                             translation=v, rotation=q)


def frame_transforms(t: float, T_base_gripper: np.ndarray, T_base_camera: np.ndarray) -> list[Visual]:
    """The tree base → gripper → camera (the camera hangs off the gripper, as it is mounted)."""
    T_gripper_camera = invert(np.asarray(T_base_gripper, float)) @ np.asarray(T_base_camera, float)
    msg = fm.FrameTransforms(transforms=[frame_transform(t, BASE, GRIPPER, T_base_gripper),
                                         frame_transform(t, GRIPPER, CAMERA, T_gripper_camera)])
    return [("/tf", "foxglove.FrameTransforms", msg.encode())]


def point_cloud(t: float, cloud: PointCloud, frame_id: str = BASE) -> bytes:
    """x, y, z float32 + red, green, blue, alpha uint8 (16-byte stride), Foxglove's packed layout."""
    xyz = np.asarray(cloud.xyz, dtype="<f4").reshape(-1, 3)
    n = len(xyz)
    rec = np.zeros(n, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
    rec["xyz"] = xyz
    if cloud.rgb is not None and len(cloud.rgb) == n:
        rec["rgba"][:, :3] = np.asarray(cloud.rgb, dtype=np.uint8)
    else:
        rec["rgba"][:, :3] = 200
    rec["rgba"][:, 3] = 255
    F, U = fm.PackedElementFieldNumericType.Float32, fm.PackedElementFieldNumericType.Uint8
    fields = [fm.PackedElementField(name=n_, offset=4 * i, type=F) for i, n_ in enumerate("xyz")]
    fields += [fm.PackedElementField(name=n_, offset=12 + i, type=U) for i, n_ in
               enumerate(("red", "green", "blue", "alpha"))]
    msg = fm.PointCloud(timestamp=stamp(t), frame_id=frame_id, pose=pose_msg(np.eye(4)), point_stride=16,
                        fields=fields, data=rec.tobytes())
    return msg.encode()


def rgbd(t: float, frame: RGBDFrame) -> list[Visual]:
    """Colour (JPEG), depth (raw 16UC1, millimetres on a D435), calibration and the believed camera pose."""
    from PIL import Image

    h, w = frame.depth.shape
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(frame.color)).save(buf, format="JPEG", quality=JPEG_QUALITY)
    color = fm.CompressedImage(timestamp=stamp(t), frame_id=CAMERA, data=buf.getvalue(), format="jpeg")
    depth = fm.RawImage(timestamp=stamp(t), frame_id=CAMERA, width=w, height=h, encoding="16UC1", step=2 * w,
                        data=np.ascontiguousarray(frame.depth, dtype="<u2").tobytes())
    i = frame.intrinsics
    calib = fm.CameraCalibration(timestamp=stamp(t), frame_id=CAMERA, width=i.width, height=i.height,
                                 distortion_model="plumb_bob", D=[0.0] * 5,
                                 K=[i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0],
                                 R=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                                 P=[i.fx, 0.0, i.cx, 0.0, 0.0, i.fy, i.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    out = [("/camera/color", "foxglove.CompressedImage", color.encode()),
           ("/camera/depth", "foxglove.RawImage", depth.encode()),
           ("/camera/calibration", "foxglove.CameraCalibration", calib.encode())]
    if frame.T_base_camera is not None:
        pose = fm.PoseInFrame(timestamp=stamp(t), frame_id=BASE, pose=pose_msg(frame.T_base_camera))
        out.append(("/camera/capture_pose", "foxglove.PoseInFrame", pose.encode()))
    return out


def for_exchange(t: float, key: str, request: Any, reply: Any) -> list[Visual]:
    """Visual messages derived from one request/reply of the orchestrator (empty when nothing to show)."""
    out: list[Visual] = []
    if isinstance(request, MoveRequest) and request.target is not None and not request.dry_run:
        frame = "/arm/target_camera" if request.frame == CAMERA else "/arm/target_gripper"
        out.append((frame, "foxglove.PoseInFrame",
                    fm.PoseInFrame(timestamp=stamp(t), frame_id=BASE, pose=pose_msg(request.target)).encode()))
    if isinstance(reply, MoveResult) and not (isinstance(request, MoveRequest) and request.dry_run):
        out += frame_transforms(t, reply.T_base_gripper, reply.T_base_camera)
    elif isinstance(reply, RGBDFrame):
        out += rgbd(t, reply)
    elif isinstance(reply, ViewResult):
        topic = "/locate/object" if reply.view < 0 else f"/views/{reply.view:02d}/object"
        out.append((topic, "foxglove.PointCloud", point_cloud(t, reply.cloud)))
    elif isinstance(reply, GraspPlanReply) and reply.grasps:
        poses = [pose_msg(g.poses["grasp"].matrix()) for g in reply.grasps if "grasp" in g.poses]
        if poses:
            out.append(("/grasps", "foxglove.PosesInFrame",
                        fm.PosesInFrame(timestamp=stamp(t), frame_id=BASE, poses=poses).encode()))
    elif isinstance(reply, ModelResult):
        out.append(("/model", "foxglove.PointCloud", point_cloud(t, reply.cloud)))
    return out


def for_sample(t: float, msg: Any) -> list[Visual]:
    """Visual messages derived from a stream sample (the arm's joint state: transforms and joints)."""
    if not isinstance(msg, JointState):
        return []
    out: list[Visual] = []
    if msg.T_base_gripper is not None and msg.T_base_camera is not None:
        out += frame_transforms(t, msg.T_base_gripper, msg.T_base_camera)
    joints = [fm.JointState(name=n, position=float(p)) for n, p in zip(msg.names, msg.position, strict=False)]
    joints.append(fm.JointState(name="gripper_opening", position=float(msg.gripper_opening)))
    out.append(("/arm/joints", "foxglove.JointStates", fm.JointStates(timestamp=stamp(t), joints=joints).encode()))
    return out

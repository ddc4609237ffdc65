"""objscan's messages as standard ROS 2 messages: plain functions, no Zenoh, used live and for bags alike.

- arm ``JointState`` -> ``sensor_msgs/msg/JointState``: names and positions as the arm reports them (rad; the
  gripper opening in m); its ``T_base_gripper`` -> ``tf2_msgs/msg/TFMessage`` ``base -> gripper`` on ``/tf``;
- hand-eye ``T_gripper_camera`` -> ``gripper -> camera`` (optical frame) on ``/tf_static``;
- a view's object centre -> ``base -> object`` on ``/tf`` (position only: axis-aligned with ``base``);
- ``RGBDFrame.color`` -> ``sensor_msgs/msg/Image`` ``rgb8``; ``.depth`` -> ``16UC1`` millimetres (ROS's
  convention; ``32FC1`` metres when the depth scale is not 1 mm); ``.intrinsics`` -> ``sensor_msgs/msg/CameraInfo``
  (``plumb_bob`` with zero distortion: the frames are rectified);
- ``PointCloud`` (view, model) -> ``sensor_msgs/msg/PointCloud2``: ``x y z`` float32 and ``rgb`` packed in a
  float32 (bits ``0x00RRGGBB``, PCL's and RViz's convention), 16 bytes a point;
- orchestrator status -> ``std_msgs/msg/String`` holding JSON: ``state``, ``status``, ``view``, ``views``,
  ``views_done``, ``progress`` (0..1), ``session``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from common.geometry import matrix_to_pose
from services.ros2.types import DEFAULT_DISTRO, msg_class

BASE, GRIPPER, CAMERA, OBJECT = "base", "gripper", "camera", "object"

# sensor_msgs/msg/PointField datatypes
FLOAT32 = 7
POINT_STEP = 16


def _t(cls: str, distro: str) -> Any:
    return msg_class(cls, distro)


def stamp(t: float, distro: str = DEFAULT_DISTRO) -> Any:
    """``builtin_interfaces/msg/Time`` of ``t`` seconds since the epoch (nanoseconds exact for ints)."""
    ns = int(round(float(t) * 1e9))
    return _t("builtin_interfaces/msg/Time", distro)(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(t_ns: int, distro: str = DEFAULT_DISTRO) -> Any:
    return _t("builtin_interfaces/msg/Time", distro)(sec=int(t_ns) // 1_000_000_000, nanosec=int(t_ns) % 1_000_000_000)


def header(t: float, frame_id: str, distro: str = DEFAULT_DISTRO) -> Any:
    return _t("std_msgs/msg/Header", distro)(stamp=stamp(t, distro), frame_id=frame_id)


def joint_state(names: list[str], position: np.ndarray, t: float, velocity: np.ndarray | None = None,
                effort: np.ndarray | None = None, distro: str = DEFAULT_DISTRO) -> Any:
    """``sensor_msgs/msg/JointState`` (empty velocity / effort when the arm does not report them)."""
    f8 = np.float64
    return _t("sensor_msgs/msg/JointState", distro)(
        header=header(t, "", distro), name=[str(n) for n in names],
        position=np.asarray(position, dtype=f8),
        velocity=np.asarray(velocity, dtype=f8) if velocity is not None else np.zeros(0, f8),
        effort=np.asarray(effort, dtype=f8) if effort is not None else np.zeros(0, f8))


def transform_stamped(T: np.ndarray, parent: str, child: str, t: float, distro: str = DEFAULT_DISTRO) -> Any:
    """``geometry_msgs/msg/TransformStamped`` of ``T_parent_child``."""
    p, q = matrix_to_pose(np.asarray(T, dtype=np.float64))
    return transform_stamped_pq(p, q, parent, child, t, distro)


def transform_stamped_pq(p: np.ndarray, q: np.ndarray, parent: str, child: str, t: float,
                         distro: str = DEFAULT_DISTRO) -> Any:
    """The same from a position and an (x, y, z, w) quaternion (computed for many poses at once by the caller)."""
    g = "geometry_msgs/msg/"
    return _t(g + "TransformStamped", distro)(
        header=header(t, parent, distro), child_frame_id=child,
        transform=_t(g + "Transform", distro)(
            translation=_t(g + "Vector3", distro)(x=float(p[0]), y=float(p[1]), z=float(p[2])),
            rotation=_t(g + "Quaternion", distro)(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))


def tf_message(transforms: list[Any], distro: str = DEFAULT_DISTRO) -> Any:
    return _t("tf2_msgs/msg/TFMessage", distro)(transforms=list(transforms))


def transform_matrix(ts: Any) -> np.ndarray:
    """Back from a ``TransformStamped`` to ``T_parent_child`` (what a TF listener computes)."""
    from common.geometry import pose_to_matrix

    tr, r = ts.transform.translation, ts.transform.rotation
    return pose_to_matrix(np.array([tr.x, tr.y, tr.z]), np.array([r.x, r.y, r.z, r.w]))


def color_image(color: np.ndarray, t: float, frame_id: str = CAMERA, distro: str = DEFAULT_DISTRO) -> Any:
    """``sensor_msgs/msg/Image`` ``rgb8`` of an (H, W, 3) uint8 image."""
    c = np.ascontiguousarray(color, dtype=np.uint8)
    h, w = c.shape[:2]
    return _t("sensor_msgs/msg/Image", distro)(header=header(t, frame_id, distro), height=h, width=w,
                                              encoding="rgb8", is_bigendian=0, step=w * 3, data=c.reshape(-1))


def depth_image(depth: np.ndarray, depth_scale: float, t: float, frame_id: str = CAMERA,
                distro: str = DEFAULT_DISTRO) -> Any:
    """``sensor_msgs/msg/Image`` of a depth map: ``16UC1`` millimetres (ROS's convention) when the depth scale
    is 1 mm, as on a D435, else ``32FC1`` metres; 0 stays 'no depth'."""
    d = np.asarray(depth)
    h, w = d.shape
    if abs(float(depth_scale) - 0.001) < 1e-12:
        data, enc, step = np.ascontiguousarray(d, dtype="<u2").view(np.uint8).reshape(-1), "16UC1", w * 2
    else:
        data = (d.astype(np.float32) * np.float32(depth_scale)).astype("<f4").view(np.uint8).reshape(-1)
        enc, step = "32FC1", w * 4
    return _t("sensor_msgs/msg/Image", distro)(header=header(t, frame_id, distro), height=h, width=w,
                                              encoding=enc, is_bigendian=0, step=step, data=data)


def camera_info(intrinsics: Any, t: float, frame_id: str = CAMERA, distro: str = DEFAULT_DISTRO) -> Any:
    """``sensor_msgs/msg/CameraInfo`` of pinhole intrinsics without distortion."""
    fx, fy, cx, cy = (float(intrinsics.fx), float(intrinsics.fy), float(intrinsics.cx), float(intrinsics.cy))
    roi = _t("sensor_msgs/msg/RegionOfInterest", distro)(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return _t("sensor_msgs/msg/CameraInfo", distro)(
        header=header(t, frame_id, distro), height=int(intrinsics.height), width=int(intrinsics.width),
        distortion_model="plumb_bob", d=np.zeros(5, np.float64),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], np.float64),
        r=np.array([1, 0, 0, 0, 1, 0, 0, 0, 1], np.float64),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], np.float64),
        binning_x=0, binning_y=0, roi=roi)


def pack_rgb(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 -> (N,) float32 whose bits are ``0x00RRGGBB`` (the ``rgb`` field RViz and PCL read)."""
    c = np.asarray(rgb, dtype=np.uint32)
    return ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).astype("<u4").view("<f4")


def unpack_rgb(packed: np.ndarray) -> np.ndarray:
    v = np.asarray(packed, dtype="<f4").view("<u4")
    return np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], axis=1).astype(np.uint8)


def point_cloud2(xyz: np.ndarray, rgb: np.ndarray | None, t: float, frame_id: str = BASE,
                 distro: str = DEFAULT_DISTRO) -> Any:
    """``sensor_msgs/msg/PointCloud2``, unorganised (height 1), little-endian, dense: x y z rgb float32."""
    pts = np.asarray(xyz, dtype=np.float32).reshape(-1, 3)
    n = len(pts)
    rec = np.zeros(n, dtype=np.dtype({"names": ["x", "y", "z", "rgb"], "formats": ["<f4"] * 4,
                                       "offsets": [0, 4, 8, 12], "itemsize": POINT_STEP}))
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    colors = np.asarray(rgb, dtype=np.uint8) if rgb is not None else np.full((n, 3), 170, np.uint8)
    rec["rgb"] = pack_rgb(colors)
    pf = _t("sensor_msgs/msg/PointField", distro)
    fields = [pf(name=name, offset=4 * i, datatype=FLOAT32, count=1) for i, name in enumerate(("x", "y", "z", "rgb"))]
    return _t("sensor_msgs/msg/PointCloud2", distro)(
        header=header(t, frame_id, distro), height=1, width=n, fields=fields, is_bigendian=False,
        point_step=POINT_STEP, row_step=POINT_STEP * n, data=rec.view(np.uint8).reshape(-1), is_dense=True)


def cloud_arrays(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """(xyz float32 (N,3), rgb uint8 (N,3)) of a PointCloud2 made by ``point_cloud2`` (read by field offsets)."""
    offs = {f.name: f.offset for f in msg.fields}
    n = int(msg.width) * int(msg.height)
    dt = np.dtype({"names": ["x", "y", "z", "rgb"], "formats": ["<f4"] * 4,
                   "offsets": [offs["x"], offs["y"], offs["z"], offs["rgb"]], "itemsize": int(msg.point_step)})
    rec = np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=dt, count=n)
    return np.stack([rec["x"], rec["y"], rec["z"]], axis=1), unpack_rgb(rec["rgb"])


def status_text(info: dict[str, Any], distro: str = DEFAULT_DISTRO) -> Any:
    """``std_msgs/msg/String`` with the orchestrator's status as a small JSON object (and its progress)."""
    views = info.get("views")
    done = info.get("views_done")
    progress = (float(done) / float(views)) if isinstance(views, (int, float)) and views and \
        isinstance(done, (int, float)) else None
    if info.get("status") == "done":
        progress = 1.0
    out = {k: info.get(k) for k in ("state", "status", "view", "views", "views_done", "session", "error")
           if info.get(k) is not None}
    out["progress"] = progress
    return _t("std_msgs/msg/String", distro)(data=json.dumps(out, default=str, sort_keys=True))

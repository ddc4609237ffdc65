"""Dense RGB-D odometry between two scans, seeded with the arm's relative camera pose.

Why this and not ICP for the default profile: with the object on a table, geometry alone leaves
directions almost unconstrained (a can's yaw about its own axis, sliding on the table), so ICP drifts
along them by degrees; the arm's poses are already right to ~1-2 mm and ~0.2°. Open3D's RGB-D odometry
(Park et al. hybrid term: photometric + depth residuals over every pixel) pins those directions with the
object's and table's texture and converges from the arm's prior in a few iterations.

Two implementations of that term (``StaticConfig.odometry_backend``): Open3D's legacy one (here) and its tensor one
prepared to minimise the same objective (``tensor_odometry.py``), ~2.6x less CPU a scan pair; ``rgbd_image`` and
``rgbd_odometry`` take the backend, so callers do not branch.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from common.messages import RGBDFrame

from .odometry_window import ImageWindow, cut_to
from .tensor_odometry import TensorPyramid, tensor_rgbd_image, tensor_rgbd_odometry

odo = o3d.pipelines.odometry

#: An odometry image of either backend.
OdometryImage = o3d.geometry.RGBDImage | TensorPyramid


def rgbd_image(frame: RGBDFrame, *, step: int, depth_min: float, depth_max: float,
               window: ImageWindow | None = None, backend: str = "legacy", levels: int = 1) -> OdometryImage:
    """The frame as an Open3D RGBD image (intensity + float depth in metres), cut to ``window`` (None: the whole
    image) and decimated by ``step``; for the ``tensor`` backend its ``levels``-level pyramid, prepared as
    ``tensor_odometry`` needs it (the legacy odometry builds its pyramid itself)."""
    if backend == "tensor":
        return tensor_rgbd_image(frame, step=step, depth_min=depth_min, depth_max=depth_max, levels=levels,
                                 window=window)
    depth = cut_to(np.asarray(frame.depth), window)[::step, ::step].astype(np.float32) * np.float32(frame.depth_scale)
    depth[depth < depth_min] = 0.0
    color = np.ascontiguousarray(cut_to(np.asarray(frame.color), window)[::step, ::step])
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(color),
        o3d.geometry.Image(np.ascontiguousarray(depth)),
        depth_scale=1.0,
        depth_trunc=depth_max,
        convert_rgb_to_intensity=True,
    )


def pinhole(frame: RGBDFrame, step: int, window: ImageWindow | None = None) -> o3d.camera.PinholeCameraIntrinsic:
    """Intrinsics of the image cut to ``window`` (None: the whole image) and ``step``-decimated: pixel i of it is
    pixel ``x0 + step*i`` of the original, so the principal point moves by the window's corner."""
    k = frame.intrinsics
    x0, y0, x1, y1 = (0, 0, k.width, k.height) if window is None else (window.x0, window.y0, window.x1, window.y1)
    w, h = len(range(x0, x1, step)), len(range(y0, y1, step))
    return o3d.camera.PinholeCameraIntrinsic(w, h, k.fx / step, k.fy / step, (k.cx - x0) / step, (k.cy - y0) / step)


def rgbd_odometry(
    source: OdometryImage,
    target: OdometryImage,
    intrinsic: o3d.camera.PinholeCameraIntrinsic,
    init: np.ndarray,
    *,
    iterations: tuple[int, ...] = (10, 5),
    max_depth_diff: float = 0.02,
    depth_min: float = 0.0,
    depth_max: float = 1.2,
    hybrid: bool = True,
    backend: str = "legacy",
) -> tuple[bool, np.ndarray]:
    """(converged, T_target_source): maps source camera points into the target camera's frame. ``backend``
    "tensor" takes images from ``rgbd_image(..., backend="tensor")``."""
    if backend == "tensor":
        return tensor_rgbd_odometry(source, target, intrinsic, init, iterations=tuple(iterations),
                                    max_depth_diff=max_depth_diff, depth_max=depth_max, hybrid=hybrid)
    option = odo.OdometryOption(o3d.utility.IntVector(list(iterations)), max_depth_diff, depth_min, depth_max)
    jac = odo.RGBDOdometryJacobianFromHybridTerm() if hybrid else odo.RGBDOdometryJacobianFromColorTerm()
    ok, T, _ = odo.compute_rgbd_odometry(source, target, intrinsic, np.asarray(init, dtype=np.float64), jac, option)
    return bool(ok), np.asarray(T).copy()

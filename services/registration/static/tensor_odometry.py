"""Open3D's tensor RGB-D odometry set up to minimise the legacy odometry's objective, at a fraction of its CPU.

Why: the legacy odometry (``odometry.py``) is two thirds of the static stage's CPU; Open3D's tensor
implementation of the same Park et al. hybrid term costs ~3x less a call on the CPU (one pass over the pixels
per iteration, no per-call correspondence maps). Called with its defaults it lands millimetres to centimetres
off the legacy result on plain symmetric shapes, because its defaults are a *different objective*, not a
different solver (docs/static-registration.md, "The tensor odometry"):

* ``depth_outlier_trunc`` 0.07 m against the legacy ``max_depth_diff`` 0.02 m: pixels across a box's silhouette
  (object in one image, table 2-7 cm behind in the other) count as matches and pull the pose; with a least-squares
  loss this alone slid box pairs by 5-8 cm.
* the photometric and depth residuals weighed 1:1 (``sqrt 0.5`` each) where the legacy weighs them
  0.032 : 0.968; intensity [0, 1] against depth in metres, so the tensor default leans ~30x more on texture.
* no smoothing: the legacy blurs intensity and depth with a 3 x 3 Gaussian before its pyramids and gradients,
  and normalises each image's intensity to a mean of 0.5 (a darker image would otherwise weigh less).
* Huber losses (``depth_huber_delta`` 0.05, ``intensity_huber_delta`` 0.1) where the legacy is least squares.

Here the images are prepared as the legacy prepares them (Gaussian 3 x 3, intensity normalised to a mean of 0.5
then scaled by ``sqrt(0.032 / 0.968)`` so the tensor's equal weights become the legacy's ratio; invalid depth, and
pixels next to it, dropped), the outlier truncation is the legacy ``max_depth_diff``, the Huber thresholds are
far above any residual the truncation lets through (a plain least-squares loss) and every pyramid level runs
exactly its iterations (tolerances 0: no early exit), so the two implementations minimise the same objective.
What stays different: the tensor's pyramid (5 x 5 Gaussian then 2 x 2 decimation; depth decimated with an edge
check) and float32 sums; measured, the results agree to a fraction of a millimetre on the sessions' pairs.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from common.messages import RGBDFrame

from .odometry_window import ImageWindow

o3c = o3d.core
t_odo = o3d.t.pipelines.odometry

#: The legacy hybrid term's weight of the depth residual (Open3D's ``LAMBDA_HYBRID_DEPTH``); the photometric
#: residual has ``1 - LAMBDA_DEPTH``.
LAMBDA_DEPTH = 0.968
#: Intensity scale that turns the tensor's equal residual weights into the legacy's ratio.
INTENSITY_WEIGHT = float(np.sqrt((1.0 - LAMBDA_DEPTH) / LAMBDA_DEPTH))
#: Huber thresholds far above any residual the outlier truncation admits: the loss is least squares, as the legacy's.
LEAST_SQUARES_DELTA = 1.0e3
#: BT.601 luma, the legacy ``convert_rgb_to_intensity`` weights.
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def _gaussian3(a: np.ndarray) -> np.ndarray:
    """Separable [1/4, 1/2, 1/4] blur with clamped borders; NaN spreads to its neighbours, as in the legacy filter."""
    p = np.pad(a, 1, mode="edge")
    h = 0.25 * p[:, :-2] + 0.5 * p[:, 1:-1] + 0.25 * p[:, 2:]
    return (0.25 * h[:-2] + 0.5 * h[1:-1] + 0.25 * h[2:]).astype(np.float32)


def _window(image: np.ndarray, window: ImageWindow | None) -> np.ndarray:
    return image if window is None else image[window.y0 : window.y1, window.x0 : window.x1]


def tensor_rgbd_image(frame: RGBDFrame, *, step: int, depth_min: float, depth_max: float,
                      window: ImageWindow | None = None) -> o3d.t.geometry.RGBDImage:
    """The frame prepared as the legacy odometry prepares it, as a tensor RGBD image: depth in float metres (0 where
    invalid, outside ``[depth_min, depth_max]`` or next to such a pixel, after the 3 x 3 blur), intensity blurred,
    normalised to a mean of 0.5 over the valid pixels and scaled by ``INTENSITY_WEIGHT`` (in all three channels, so
    the tensor's grey conversion keeps it). Cut to ``window`` (None: the whole image), decimated by ``step``."""
    depth = _window(np.asarray(frame.depth), window)[::step, ::step].astype(np.float32) * np.float32(frame.depth_scale)
    depth[(depth < depth_min) | (depth > depth_max) | ~np.isfinite(depth)] = np.nan
    depth = _gaussian3(depth)
    depth[~np.isfinite(depth)] = 0.0
    rgb = _window(np.asarray(frame.color), window)[::step, ::step].astype(np.float32)
    gray = _gaussian3((rgb @ _LUMA) / np.float32(255.0))
    valid = depth > 0
    mean = float(gray[valid].mean()) if valid.any() else float(gray.mean())
    gray *= np.float32((0.5 / mean if mean > 0 else 1.0) * INTENSITY_WEIGHT)
    color = np.ascontiguousarray(np.repeat(gray[:, :, None], 3, axis=2))
    return o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3c.Tensor(color)),
                                    o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth))))


def tensor_rgbd_odometry(
    source: o3d.t.geometry.RGBDImage,
    target: o3d.t.geometry.RGBDImage,
    intrinsic: o3d.camera.PinholeCameraIntrinsic,
    init: np.ndarray,
    *,
    iterations: tuple[int, ...],
    max_depth_diff: float,
    depth_max: float,
    hybrid: bool = True,
) -> tuple[bool, np.ndarray]:
    """(converged, T_target_source), as ``odometry.rgbd_odometry``: the same pyramid levels (coarse to fine), each
    run for exactly its iterations; not converged when Open3D finds no valid pixel pair or the pose is not finite."""
    K = o3c.Tensor(np.asarray(intrinsic.intrinsic_matrix, dtype=np.float64))
    criteria = [t_odo.OdometryConvergenceCriteria(int(n), 0.0, 0.0) for n in iterations]
    params = t_odo.OdometryLossParams(float(max_depth_diff), LEAST_SQUARES_DELTA, LEAST_SQUARES_DELTA)
    method = t_odo.Method.Hybrid if hybrid else t_odo.Method.Intensity
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        try:
            result = t_odo.rgbd_odometry_multi_scale(source, target, K, o3c.Tensor(np.asarray(init, dtype=np.float64)),
                                                     1.0, float(depth_max), criteria, method, params)
        except RuntimeError:  # Open3D raises when no pixel pair is left (inlier count 0)
            return False, np.asarray(init, dtype=np.float64).copy()
    T = result.transformation.numpy().astype(np.float64)
    return bool(np.isfinite(T).all()), T

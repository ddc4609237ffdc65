"""Open3D's tensor RGB-D odometry set up to minimise the legacy odometry's objective, at a fraction of its CPU.

Why: the legacy odometry (``odometry.py``) is two thirds of the static stage's CPU; Open3D's tensor
implementation of the same Park et al. hybrid term costs less than half as much on the CPU (one pass over the
pixels per iteration, no per-call correspondence maps). Called with its defaults it lands millimetres to
centimetres off the legacy result on plain symmetric shapes, because its defaults are a *different objective*, not
a different solver (docs/static-registration.md, "The tensor odometry"):

* ``depth_outlier_trunc`` 0.07 m against the legacy ``max_depth_diff`` 0.02 m: pixels across a box's silhouette
  (object in one image, table 2-7 cm behind in the other) count as matches and pull the pose.
* the photometric and depth residuals weighed 1:1 (``sqrt 0.5`` each) where the legacy weighs them
  0.032 : 0.968, intensity in [0, 1] against depth in metres: the tensor default leans ~30x more on texture.
* no smoothing: the legacy blurs intensity and depth with a 3 x 3 Gaussian before its pyramid and gradients, and
  normalises each image's intensity to a mean of 0.5 (a darker image would otherwise weigh less).
* Huber losses (``depth_huber_delta`` 0.05, ``intensity_huber_delta`` 0.1) where the legacy is least squares.
* its own pyramid: depth decimated by an edge-preserving 5 x 5 filter, where the legacy averages 2 x 2 blocks (a
  block across a silhouette gets a mixed depth that then fails the 2 cm test, or NaN next to a hole). With every
  other setting matched, the coarsest (160 x 120) level alone still slid a cup by 5-7 mm on 5 of 12 pairs.

So here the images are prepared as the legacy prepares them and the pyramid is built as the legacy builds it
(``TensorPyramid``: 3 x 3 Gaussian on intensity and depth, invalid depth and its neighbours dropped, intensity
normalised to a mean of 0.5 and scaled by ``sqrt(0.032 / 0.968)`` so the tensor's equal weights become the
legacy's ratio; each coarser level the 3 x 3-blurred intensity and the plain depth averaged over 2 x 2 blocks), and
the tensor odometry runs one level per call (a one-level ``criteria_list``: no pyramid of its own) with the outlier
truncation at the legacy ``max_depth_diff``, Huber thresholds far above any residual it admits (a least-squares
loss) and tolerances 0 (exactly the configured iterations, as the legacy). What stays different: float32 sums,
and a pixel whose depth gradient is undefined (next to a hole) is dropped where the legacy keeps it with a zero
depth gradient.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.messages import RGBDFrame

from .odometry_window import ImageWindow, cut_to

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


@dataclass(frozen=True)
class TensorPyramid:
    """A frame's odometry images, finest level first, each a tensor RGBD image (intensity in all three channels,
    depth in float metres, 0 where invalid)."""

    levels: tuple[o3d.t.geometry.RGBDImage, ...]


def _gaussian3(a: np.ndarray) -> np.ndarray:
    """Separable [1/4, 1/2, 1/4] blur with clamped borders; NaN spreads to its neighbours, as in the legacy filter."""
    p = np.pad(a, 1, mode="edge")
    h = 0.25 * p[:, :-2] + 0.5 * p[:, 1:-1] + 0.25 * p[:, 2:]
    return (0.25 * h[:-2] + 0.5 * h[1:-1] + 0.25 * h[2:]).astype(np.float32)


def _halve(a: np.ndarray) -> np.ndarray:
    """Mean of each 2 x 2 block (NaN when any of the four is), as the legacy image pyramid's downsampling."""
    h, w = a.shape[0] // 2 * 2, a.shape[1] // 2 * 2
    a = a[:h, :w]
    return ((a[0::2, 0::2] + a[0::2, 1::2] + a[1::2, 0::2] + a[1::2, 1::2]) * np.float32(0.25)).astype(np.float32)


def _level(gray: np.ndarray, depth: np.ndarray) -> o3d.t.geometry.RGBDImage:
    depth = np.where(np.isfinite(depth), depth, np.float32(0.0)).astype(np.float32)
    color = np.ascontiguousarray(np.repeat(gray[:, :, None], 3, axis=2))
    return o3d.t.geometry.RGBDImage(o3d.t.geometry.Image(o3c.Tensor(color)),
                                    o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth))))


def tensor_rgbd_image(frame: RGBDFrame, *, step: int, depth_min: float, depth_max: float, levels: int,
                      window: ImageWindow | None = None) -> TensorPyramid:
    """The frame's ``levels``-level odometry pyramid, prepared as the legacy odometry prepares its images (module
    docstring), cut to ``window`` (None: the whole image) and decimated by ``step`` first."""
    depth = cut_to(np.asarray(frame.depth), window)[::step, ::step].astype(np.float32) * np.float32(frame.depth_scale)
    depth[(depth < depth_min) | (depth > depth_max) | (depth <= 0)] = np.nan
    depth = _gaussian3(depth)
    rgb = cut_to(np.asarray(frame.color), window)[::step, ::step].astype(np.float32)
    gray = _gaussian3((rgb @ _LUMA) / np.float32(255.0))
    valid = np.isfinite(depth)
    mean = float(gray[valid].mean()) if valid.any() else float(gray.mean())
    gray *= np.float32((0.5 / mean if mean > 0 else 1.0) * INTENSITY_WEIGHT)
    out = [_level(gray, depth)]
    for _ in range(levels - 1):
        gray, depth = _halve(_gaussian3(gray)), _halve(depth)
        out.append(_level(gray, depth))
    return TensorPyramid(tuple(out))


def tensor_rgbd_odometry(
    source: TensorPyramid,
    target: TensorPyramid,
    intrinsic: o3d.camera.PinholeCameraIntrinsic,
    init: np.ndarray,
    *,
    iterations: tuple[int, ...],
    max_depth_diff: float,
    depth_max: float,
    hybrid: bool = True,
) -> tuple[bool, np.ndarray]:
    """(converged, T_target_source), as ``odometry.rgbd_odometry``: ``iterations`` per pyramid level, coarse to fine
    (the pyramids need at least that many levels), each level run for exactly its iterations from the previous
    level's pose; the intrinsics halve per level as the legacy's. Not converged when Open3D finds no valid pixel
    pair or the pose is not finite."""
    n = len(iterations)
    if len(source.levels) < n or len(target.levels) < n:
        raise ValueError(f"{n} pyramid levels asked, the images have {len(source.levels)} and {len(target.levels)}")
    K = np.asarray(intrinsic.intrinsic_matrix, dtype=np.float64)
    method = t_odo.Method.Hybrid if hybrid else t_odo.Method.Intensity
    T = np.asarray(init, dtype=np.float64).copy()
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):  # "Huber degenerates to L2": meant
        params = t_odo.OdometryLossParams(float(max_depth_diff), LEAST_SQUARES_DELTA, LEAST_SQUARES_DELTA)
        for i, count in enumerate(iterations):
            level = n - 1 - i
            if count <= 0:
                continue
            K_level = K / 2.0**level
            K_level[2, 2] = 1.0
            try:
                result = t_odo.rgbd_odometry_multi_scale(
                    source.levels[level], target.levels[level], o3c.Tensor(K_level), o3c.Tensor(T), 1.0,
                    float(depth_max), [t_odo.OdometryConvergenceCriteria(int(count), 0.0, 0.0)], method, params)
            except RuntimeError:  # Open3D raises when no pixel pair is left (inlier count 0)
                return False, np.asarray(init, dtype=np.float64).copy()
            T = result.transformation.numpy().astype(np.float64)
    return bool(np.isfinite(T).all()), T

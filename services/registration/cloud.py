"""Point-cloud utilities shared by the registration stages.

One job each: turn an ``RGBDFrame`` into colored points (in ``camera`` or ``base``), voxel down-sample and
estimate normals with Open3D's legacy API (the fast one on CPU, see ecosystem-notes §5), read and write PLY
with xyz/rgb/normals, and convert between Open3D, numpy and the wire ``PointCloud``. Keeping these
conversions in one place means every stage agrees on dtypes (xyz float32 on the wire, float64 inside
Open3D) and color scale (uint8 on the wire, [0, 1] floats inside Open3D).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import open3d as o3d

from common.atomic import atomic_path
from common.errors import ObjscanError
from common.geometry import as_rigid_transform, rotate_vectors, transform_points
from common.messages import PointCloud, RGBDFrame

_O3D_RANDOM = threading.RLock()


@contextmanager
def o3d_seeded(seed: int) -> Iterator[None]:
    """Seed Open3D's one global random generator and hold it for the block (a RANSAC call).

    Why a lock: ``objscan reconstruct`` registers views in threads (``reconstruct.py``); two threads that
    seed and then draw from the one generator would interleave and lose reproducibility. The seed is folded
    into Open3D's 31-bit range.
    """
    with _O3D_RANDOM:
        o3d.utility.random.seed(int(seed) & 0x7FFFFFFF)
        yield


class CloudError(ObjscanError):
    """A cloud or frame given to a cloud utility is unusable (wrong shape, NaN, empty, unreadable)."""

    code = "bad_cloud"


@dataclass
class FramePoints:
    """Back-projected valid pixels of one frame: positions, colors and the flat pixel index of each point.

    ``pixel`` lets a caller look up per-pixel data (e.g. the simulator's ground-truth labels) for a point.
    """

    xyz: np.ndarray  # (N, 3) float64, in the frame asked for
    rgb: np.ndarray  # (N, 3) uint8
    pixel: np.ndarray  # (N,) int64, row * width + col

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def subset(self, mask: np.ndarray) -> FramePoints:
        return FramePoints(self.xyz[mask], self.rgb[mask], self.pixel[mask])


@lru_cache(maxsize=8)
def _ray_grid(width: int, height: int, fx: float, fy: float, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel (x/z, y/z) of the pinhole rays; cached because every frame of a camera shares it."""
    u = (np.arange(width, dtype=np.float64) - cx) / fx
    v = (np.arange(height, dtype=np.float64) - cy) / fy
    return np.broadcast_to(u[None, :], (height, width)).ravel(), np.broadcast_to(v[:, None], (height, width)).ravel()


def check_frame(frame: RGBDFrame) -> None:
    """Raise ``CloudError`` for a frame whose arrays cannot be back-projected (shape, dtype, NaN pose)."""
    depth, color = np.asarray(frame.depth), np.asarray(frame.color)
    if depth.ndim != 2:
        raise CloudError("depth must be a 2-D image", code="bad_shape", detail={"shape": list(depth.shape)})
    if color.ndim != 3 or color.shape[2] != 3 or color.shape[:2] != depth.shape:
        raise CloudError(
            "color must be (H, W, 3) matching depth",
            code="bad_shape",
            detail={"color": list(color.shape), "depth": list(depth.shape)},
        )
    intr = frame.intrinsics
    if (intr.width, intr.height) != (depth.shape[1], depth.shape[0]):
        raise CloudError(
            "image size differs from intrinsics",
            code="bad_shape",
            detail={"image": [depth.shape[1], depth.shape[0]], "intrinsics": [intr.width, intr.height]},
        )
    if not (intr.fx > 0 and intr.fy > 0 and np.isfinite([intr.fx, intr.fy, intr.cx, intr.cy]).all()):
        raise CloudError("intrinsics must be finite with positive focal lengths", code="bad_value")
    if not (np.isfinite(frame.depth_scale) and frame.depth_scale > 0):
        raise CloudError("depth_scale must be positive", code="bad_value", detail={"depth_scale": frame.depth_scale})
    if (frame.meta or {}).get("pose_source") == "unknown":  # the identity stood in for a failed pose query
        raise CloudError("frame has no camera pose (pose_source=unknown: the pose query failed when it was "
                         "captured); it cannot be placed in base", code="no_camera_pose")
    as_rigid_transform(frame.T_base_camera, "T_base_camera", CloudError)


def depth_edge_mask(depth_m: np.ndarray, threshold: float) -> np.ndarray:
    """True where a pixel's depth jumps by more than ``threshold`` (m) to one of its 8 valid neighbours.

    Those are silhouette pixels and the "flying pixels" a stereo camera blends between a foreground edge
    and the background behind it: points that float in space near the object but belong to neither.
    """
    z = np.asarray(depth_m, dtype=np.float32)
    h, w = z.shape
    pad = np.pad(z, 1, mode="constant", constant_values=0.0)
    edge = np.zeros((h, w), dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy == 0 and dx == 0:
                continue
            nb = pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            edge |= (nb > 0) & (np.abs(nb - z) > threshold)
    return edge & (z > 0)


def frame_points(
    frame: RGBDFrame,
    *,
    depth_min: float = 0.1,
    depth_max: float = 1.5,
    T: np.ndarray | None = None,
    stride: int = 1,
    edge_threshold: float | None = None,
) -> FramePoints:
    """Back-project the valid depth pixels of ``frame``.

    Points come out in ``camera`` when ``T`` is None, else mapped by ``T`` (pass ``frame.T_base_camera``
    for ``base``). Depth outside ``[depth_min, depth_max]`` (including the 0 = no-return value) is dropped;
    ``stride`` > 1 takes every stride-th row and column, a cheap preview. With ``edge_threshold`` (m),
    pixels at a depth discontinuity larger than that are dropped (see ``depth_edge_mask``).
    """
    check_frame(frame)
    depth = np.asarray(frame.depth)
    h, w = depth.shape
    intr = frame.intrinsics
    gx, gy = _ray_grid(w, h, float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy))
    z = depth.ravel().astype(np.float64) * frame.depth_scale
    keep = (z >= depth_min) & (z <= depth_max)
    if edge_threshold is not None:
        keep &= ~depth_edge_mask(z.reshape(h, w), edge_threshold).ravel()
    if stride > 1:
        grid = np.zeros((h, w), dtype=bool)
        grid[::stride, ::stride] = True
        keep &= grid.ravel()
    idx = np.flatnonzero(keep)
    zk = z[idx]
    xyz = np.column_stack([gx[idx] * zk, gy[idx] * zk, zk])
    if T is not None:
        xyz = transform_points(np.asarray(T, dtype=np.float64), xyz)
    rgb = np.asarray(frame.color).reshape(-1, 3)[idx]
    return FramePoints(xyz=xyz, rgb=np.ascontiguousarray(rgb, dtype=np.uint8), pixel=idx.astype(np.int64))


def frame_to_cloud(
    frame: RGBDFrame, *, depth_min: float = 0.1, depth_max: float = 1.5, in_base: bool = True
) -> PointCloud:
    """The frame as a wire ``PointCloud`` (no normals), in ``base`` (believed pose) or in ``camera``."""
    pts = frame_points(frame, depth_min=depth_min, depth_max=depth_max, T=frame.T_base_camera if in_base else None)
    return PointCloud(xyz=pts.xyz.astype(np.float32), rgb=pts.rgb, normals=None, frame="base" if in_base else "camera")


def _check_xyz(xyz: np.ndarray, what: str = "xyz") -> np.ndarray:
    arr = np.asarray(xyz)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise CloudError(f"{what} must be (N, 3)", code="bad_shape", detail={"shape": list(arr.shape)})
    if not np.isfinite(arr).all():
        raise CloudError(f"{what} contains NaN or inf", code="bad_value")
    return arr


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) chromaticity r, g, b / (r + g + b) of colours on the 0-255 scale (uint8, or averaged floats).

    The ratio does not change with brightness, so colours compare across shading and lighting. One count is
    added to each channel first: an 8-bit camera's dark pixels are mostly quantisation noise, and without it
    (0, 0, 2) would read as saturated blue, (2, 0, 0) as saturated red: an L1 difference of 2, the largest there
    is, between two nearly black points. With it they differ by 0.8, black is neutral grey (1/3 each) and a
    colour moves continuously toward grey as it darkens, so no cut-off for "too dark" is needed.
    """
    c = np.asarray(rgb, dtype=np.float64).reshape(-1, 3) + 1.0
    return c / c.sum(axis=1, keepdims=True)


def to_o3d(
    xyz: np.ndarray | PointCloud, rgb: np.ndarray | None = None, normals: np.ndarray | None = None
) -> o3d.geometry.PointCloud:
    """An Open3D legacy cloud from numpy arrays (rgb uint8 0..255) or from a wire ``PointCloud``."""
    if isinstance(xyz, PointCloud):
        xyz, rgb, normals = xyz.xyz, xyz.rgb, xyz.normals
    arr = _check_xyz(xyz)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(arr.astype(np.float64)))
    for name, extra in (("rgb", rgb), ("normals", normals)):
        if extra is not None and np.asarray(extra).shape != arr.shape:
            raise CloudError(
                f"{name} shape differs from xyz",
                code="bad_shape",
                detail={name: list(np.asarray(extra).shape), "xyz": list(arr.shape)},
            )
    if rgb is not None:
        pcd.colors = o3d.utility.Vector3dVector(np.asarray(rgb, dtype=np.float64) / 255.0)
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(_check_xyz(normals, "normals").astype(np.float64))
    return pcd


def from_o3d(pcd: o3d.geometry.PointCloud, frame: str = "base") -> PointCloud:
    """A wire ``PointCloud`` (xyz float32, rgb uint8, normals float32) from an Open3D legacy cloud."""
    xyz = np.asarray(pcd.points, dtype=np.float32).reshape(-1, 3)
    rgb = np.clip(np.asarray(pcd.colors) * 255.0 + 0.5, 0, 255).astype(np.uint8) if pcd.has_colors() else None
    normals = np.asarray(pcd.normals, dtype=np.float32) if pcd.has_normals() else None
    return PointCloud(xyz=xyz, rgb=rgb, normals=normals, frame=frame)


def estimate_normals(
    pcd: o3d.geometry.PointCloud, radius: float, *, max_nn: int = 30, toward: np.ndarray | None = None
) -> o3d.geometry.PointCloud:
    """Estimate normals in place (hybrid radius/k search) and flip them toward ``toward`` if given.

    Orienting toward the camera is what makes normals of a single-sided scan consistent, which colored
    ICP, point-to-plane ICP and the PLY consumers rely on.
    """
    if len(pcd.points) == 0:
        return pcd
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn))
    if toward is not None:
        pts = np.asarray(pcd.points)
        nrm = np.asarray(pcd.normals)
        flip = np.einsum("ij,ij->i", nrm, np.asarray(toward, dtype=np.float64).reshape(-1, 3) - pts) < 0
        nrm[flip] *= -1.0
        pcd.normals = o3d.utility.Vector3dVector(nrm)
    return pcd


def downsample(
    pcd: o3d.geometry.PointCloud,
    voxel: float,
    *,
    normals: bool = True,
    normal_radius_factor: float = 2.5,
    max_nn: int = 30,
    toward: np.ndarray | None = None,
) -> o3d.geometry.PointCloud:
    """Voxel-grid down-sample (voxel centroid of points and colors) and optionally estimate normals.

    This is the paper's pre-processing step: every registration input is down-sampled and gets normals.
    """
    if voxel <= 0:
        raise CloudError("voxel size must be positive", code="bad_value", detail={"voxel": voxel})
    out = pcd.voxel_down_sample(voxel)
    if normals:
        estimate_normals(out, voxel * normal_radius_factor, max_nn=max_nn, toward=toward)
    return out


def transform_cloud(cloud: PointCloud, T: np.ndarray, frame: str | None = None) -> PointCloud:
    """``cloud`` mapped by ``T`` (points and normals), keeping colors."""
    xyz = transform_points(np.asarray(T, dtype=np.float64), cloud.xyz.astype(np.float64)).astype(np.float32)
    nrm = None if cloud.normals is None else rotate_vectors(T, cloud.normals.astype(np.float64)).astype(np.float32)
    return PointCloud(xyz=xyz, rgb=cloud.rgb, normals=nrm, frame=frame or cloud.frame)


def write_ply(path: Path | str, cloud: PointCloud | o3d.geometry.PointCloud, *, binary: bool = True) -> Path:
    """Write xyz (+ rgb, + normals when present) to a PLY file; parent folders are created."""
    path = Path(path)
    pcd = cloud if isinstance(cloud, o3d.geometry.PointCloud) else to_o3d(cloud)
    # unique temporary name, fsync, rename, folder fsync: a reader never sees a half-written file, two
    # writers never share a temporary file, and a failed write (disk full) raises instead of renaming
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), pcd, write_ascii=not binary) or tmp.stat().st_size == 0:
            raise CloudError(f"could not write {path}", code="io_error")
    return path


def read_ply(path: Path | str, frame: str = "base") -> PointCloud:
    """Read a point cloud file (PLY, PCD, ...) into a wire ``PointCloud``."""
    path = Path(path)
    if not path.is_file():
        raise CloudError(f"{path} does not exist", code="io_error")
    pcd = o3d.io.read_point_cloud(str(path))
    if len(pcd.points) == 0:
        raise CloudError(f"{path} holds no points", code="empty_cloud")
    return from_o3d(pcd, frame=frame)

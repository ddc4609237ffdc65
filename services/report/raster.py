"""CPU point rendering without a display: project, z-buffer, splat; plus a colormap and PNG encoding.

Open3D's offscreen renderer needs EGL or a GPU, which CI machines and lab laptops without a display may
not have; a point model renders well enough by splatting every point as a small disk into a z-buffer.
All numpy, ~0.1 s for 100k points at 600x450. Normals, when given, shade the colors (Lambert, light from
the camera) so the shape reads.
"""

from __future__ import annotations

import base64
import io
from dataclasses import dataclass

import numpy as np
from PIL import Image

from common.geometry import invert, look_at
from services.report.errors import ReportError

#: viridis at 9 evenly spaced stops (perceptually uniform, colour-blind safe); interpolated linearly.
_VIRIDIS = np.array([[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
                     [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]], dtype=np.float64)


@dataclass(frozen=True)
class RasterCamera:
    """The report's pinhole camera for rasterising points (not a ``services.camera`` backend):
    ``T_world_camera`` (optical frame: z forward, x right, y down) and intrinsics."""

    T_world_camera: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


def colormap(values: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """uint8 (N, 3) viridis colors of ``values`` clipped to [vmin, vmax]."""
    v = np.asarray(values, dtype=np.float64)
    t = np.clip((v - vmin) / max(vmax - vmin, 1e-12), 0.0, 1.0) * (len(_VIRIDIS) - 1)
    i = np.minimum(np.floor(t).astype(int), len(_VIRIDIS) - 2)
    f = (t - i)[:, None]
    return np.round(_VIRIDIS[i] * (1 - f) + _VIRIDIS[i + 1] * f).astype(np.uint8)


def orbit_camera(center: np.ndarray, radius: float, azimuth_deg: float, elevation_deg: float,
                 width: int = 480, height: int = 360, fill: float = 0.8) -> RasterCamera:
    """A camera on a sphere around ``center`` (z up) looking at it, zoomed so a ball of ``radius`` fills
    ``fill`` of the shorter image side."""
    if radius <= 0 or not np.isfinite(radius):
        raise ReportError("orbit radius must be positive", code="bad_value", detail={"radius": radius})
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    distance = 4.0 * radius
    eye = np.asarray(center, float) + distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                                           np.sin(el)])
    T = look_at(eye, center, (0.0, 0.0, 1.0))
    if T[2, 1] > 0:  # keep world-up pointing up in the image
        T[:3, :2] = -T[:3, :2]
    f = fill * 0.5 * min(width, height) * distance / radius
    return RasterCamera(T, f, f, width / 2.0, height / 2.0, width, height)


def render_points(xyz: np.ndarray, rgb: np.ndarray | None, camera: RasterCamera, *, normals: np.ndarray | None = None,
                  radius_px: int = 1, background: tuple[int, int, int] = (255, 255, 255)) -> np.ndarray:
    """(H, W, 3) uint8 image of the points seen by ``camera``; each point a disk of ``radius_px``.

    Nearest point wins per pixel (z-buffer). Points behind the camera are dropped. ``rgb`` None draws grey.
    """
    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ReportError("points must be (N, 3)", code="bad_shape", detail={"shape": list(pts.shape)})
    colors = np.full(pts.shape, 170.0) if rgb is None else np.asarray(rgb, dtype=np.float64)
    if colors.shape != pts.shape:
        raise ReportError("colors must match the points", code="bad_shape")
    ok = np.isfinite(pts).all(axis=1)
    T_cw = invert(np.asarray(camera.T_world_camera, dtype=np.float64))
    pc = pts[ok] @ T_cw[:3, :3].T + T_cw[:3, 3]
    col = colors[ok]
    if normals is not None:
        n = np.asarray(normals, dtype=np.float64)[ok] @ T_cw[:3, :3].T
        lit = np.abs(n[:, 2]) / np.maximum(np.linalg.norm(n, axis=1), 1e-12)  # light from the camera
        col = col * (0.45 + 0.55 * lit[:, None])
    front = pc[:, 2] > 1e-6
    pc, col = pc[front], col[front]
    u = np.round(camera.fx * pc[:, 0] / pc[:, 2] + camera.cx).astype(np.int64)
    v = np.round(camera.fy * pc[:, 1] / pc[:, 2] + camera.cy).astype(np.int64)
    r = max(int(radius_px), 0)
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    disk = (dx**2 + dy**2) <= r * r + r  # a round-ish splat
    dx, dy = dx[disk], dy[disk]
    uu = (u[:, None] + dx[None, :]).ravel()
    vv = (v[:, None] + dy[None, :]).ravel()
    src = np.repeat(np.arange(u.size), dx.size)
    inside = (uu >= 0) & (uu < camera.width) & (vv >= 0) & (vv < camera.height)
    pix, src = vv[inside] * camera.width + uu[inside], src[inside]
    image = np.empty((camera.height * camera.width, 3), dtype=np.uint8)
    image[:] = background
    if pix.size:
        order = np.lexsort((pc[src, 2], pix))  # by pixel, nearest first
        pix_sorted = pix[order]
        first = np.r_[True, pix_sorted[1:] != pix_sorted[:-1]]
        win = order[first]
        image[pix[win]] = np.clip(np.round(col[src[win]]), 0, 255).astype(np.uint8)
    return image.reshape(camera.height, camera.width, 3)


def png_data_uri(image: np.ndarray | Image.Image, max_side: int | None = None) -> str:
    """A ``data:image/png;base64,...`` URI of an image (downscaled so its longer side <= ``max_side``)."""
    img = image if isinstance(image, Image.Image) else Image.fromarray(np.ascontiguousarray(image))
    if max_side is not None and max(img.size) > max_side:
        s = max_side / max(img.size)
        img = img.resize((max(1, round(img.width * s)), max(1, round(img.height * s))), Image.LANCZOS)
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")

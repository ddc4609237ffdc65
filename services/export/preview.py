"""A picture of an exported mesh without a GPU: ray casting through the textured triangles (docs, reports).

Open3D's offscreen renderer needs EGL or a display; Open3D's CPU ray casting scene gives, per pixel, the
triangle hit and its barycentric coordinates, from which the albedo is sampled through the UVs and shaded
with a headlight (Lambert + ambient).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
from PIL import Image

from common.geometry import look_at


def render(path: str | Path, width: int = 640, height: int = 640, azimuth_deg: float = 35.0,
           elevation_deg: float = 25.0, background: tuple[int, int, int] = (255, 255, 255)) -> np.ndarray:
    """(H, W, 3) uint8 picture of the textured mesh file ``path`` (OBJ/GLB) seen from an oblique view."""
    import trimesh

    loaded = trimesh.load(str(path), force="mesh")
    v = np.asarray(loaded.vertices, dtype=np.float64)
    f = np.asarray(loaded.faces, dtype=np.int64)
    visual = loaded.visual
    uv = getattr(visual, "uv", None)
    image = getattr(getattr(visual, "material", None), "baseColorTexture", None) \
        or getattr(getattr(visual, "material", None), "image", None)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32)))
    centre = (v.min(axis=0) + v.max(axis=0)) / 2
    radius = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) / 2
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    eye = centre + 2.6 * radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    T = look_at(eye, centre)
    fpx = 0.5 * width / np.tan(np.radians(22.5))
    K = np.array([[fpx, 0, width / 2], [0, fpx, height / 2], [0, 0, 1]])
    rays = scene.create_rays_pinhole(o3d.core.Tensor(K), o3d.core.Tensor(np.linalg.inv(T)), width, height)
    hit = scene.cast_rays(rays)
    prim = hit["primitive_ids"].numpy().astype(np.int64)
    ok = np.isfinite(hit["t_hit"].numpy())
    out = np.empty((height, width, 3), dtype=np.float64)
    out[:] = background
    tri = prim[ok]
    b = hit["primitive_uvs"].numpy()[ok]
    w = np.column_stack([1.0 - b[:, 0] - b[:, 1], b[:, 0], b[:, 1]])
    if uv is not None and image is not None:
        tex = np.asarray(image.convert("RGB"), dtype=np.float64)
        uvp = np.einsum("nk,nkj->nj", w, np.asarray(uv)[f[tri]])
        x = np.clip((uvp[:, 0] % 1.0) * tex.shape[1], 0, tex.shape[1] - 1).astype(np.int64)
        y = np.clip((1.0 - uvp[:, 1] % 1.0) * tex.shape[0], 0, tex.shape[0] - 1).astype(np.int64)
        colour = tex[y, x]
    elif getattr(visual, "vertex_colors", None) is not None:
        colour = np.einsum("nk,nkj->nj", w, np.asarray(visual.vertex_colors, dtype=np.float64)[f[tri], :3])
    else:
        colour = np.full((len(tri), 3), 180.0)
    normals = hit["primitive_normals"].numpy()[ok]
    dirs = rays.numpy()[..., 3:][ok]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    shade = 0.35 + 0.65 * np.abs(np.einsum("ij,ij->i", normals, dirs))
    out[ok] = colour * shade[:, None]
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def save_render(path: str | Path, png: str | Path, **kwargs) -> Path:  # noqa: ANN003
    """Render ``path`` and write the picture to ``png``."""
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(render(path, **kwargs)).save(png)
    return png

"""CPU RGB-D rendering of the twin with Open3D's ``RaycastingScene``.

One ray per pixel through the pixel centre ``(u, v)`` of a pinhole camera (the same convention a
registration back-projects with: ``x = (u - cx) / fx * z``). Ray directions have z = 1 in the camera
frame, so the hit distance *is* the z-depth. At each hit the surface colour is the object's texture
sampled through the triangle's UVs (barycentrics from ``primitive_uvs``) or the table's procedural wood
texture, shaded with a fixed room light (Lambert + ambient), then the D435 model degrades the images.

The ``RaycastingScene`` (its BVH) is built once per world state in ``RenderScene`` and reused for every
frame until the object moves.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import open3d as o3d
from numba import njit
from scipy.ndimage import gaussian_filter

from common.messages import Intrinsics, d435_intrinsics
from services.sim.catalogue import DEFAULT_COLOR, SimObject
from services.sim.errors import SimInputError, check_transform
from services.sim.sensor_model import D435Noise, apply_d435_noise

LABEL_NONE = 0
LABEL_TABLE = 1
LABEL_OBJECT = 2
LABEL_EXTRA = 3  # extra scene geometry (a wall, a second box): clutter the object must be isolated from
#: Colour of pixels whose ray hits nothing (the far room): dark grey, no depth.
BACKGROUND_RGB = np.array([55, 58, 62], dtype=np.uint8)


@dataclass(frozen=True)
class TableSpec:
    """The table: a box whose top is the plane z = 0 of ``base`` (docs/conventions.md), spanning well
    beyond the arm's reach around the object's default place (0.5, 0)."""

    center_xy: tuple[float, float] = (0.5, 0.0)
    size_xy: tuple[float, float] = (1.6, 1.6)
    thickness: float = 0.04
    texel_m: float = 0.002  # resolution of the procedural top texture
    base_rgb: tuple[int, int, int] = (176, 146, 110)  # light wood
    grain_contrast: float = 22.0  # 8-bit levels of the wood grain and blotches (what colour ICP locks on)
    texture_seed: int = 7


@dataclass(frozen=True)
class SceneBox:
    """Extra geometry for the twin's scene: a flat-coloured box in ``base`` (a wall, a second object).

    Real cells are not just a table and one object; walls, shelves and other boxes are in view, and the
    registration must find the table and the right object among them. ``yaw_deg`` turns the box about
    base z through its centre.
    """

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw_deg: float = 0.0
    rgb: tuple[int, int, int] = (200, 200, 195)

    def mesh(self) -> o3d.geometry.TriangleMesh:
        sx, sy, sz = self.size
        if min(sx, sy, sz) <= 0:
            raise SimInputError("a scene box needs a positive size", code="bad_value", detail={"size": self.size})
        m = o3d.geometry.TriangleMesh.create_box(sx, sy, sz)
        m.translate((-sx / 2, -sy / 2, -sz / 2))
        c, s = np.cos(np.radians(self.yaw_deg)), np.sin(np.radians(self.yaw_deg))
        m.rotate(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), center=(0.0, 0.0, 0.0))
        m.translate(self.center)
        return m


def wall_behind(object_xy: tuple[float, float] = (0.5, 0.0), distance: float = 0.3) -> SceneBox:
    """A wall ``distance`` behind an object at ``object_xy``, as seen from the arm (farther along +x)."""
    return SceneBox(center=(object_xy[0] + distance + 0.01, object_xy[1], 0.4), size=(0.02, 1.6, 0.8),
                    rgb=(214, 210, 198))


@dataclass(frozen=True)
class Lighting:
    """A fixed room light: colour = albedo * (ambient + diffuse * max(0, n . towards_light))."""

    towards_light: tuple[float, float, float] = (-0.3, 0.25, 1.0)
    ambient: float = 0.55
    diffuse: float = 0.5


@lru_cache(maxsize=8)
def table_texture(spec: TableSpec) -> np.ndarray:
    """Procedural wood-like texture of the table top, (rows along y, cols along x, 3) uint8, read-only.

    Grain along x plus soft blotches at two scales: mild, but enough structure for colour ICP and for a
    person to see the table move between frames.
    """
    rng = np.random.default_rng(spec.texture_seed)
    nx = max(2, int(round(spec.size_xy[0] / spec.texel_m)))
    ny = max(2, int(round(spec.size_xy[1] / spec.texel_m)))
    blotch = gaussian_filter(rng.standard_normal((ny, nx)), 12.0)
    blotch /= np.abs(blotch).max() + 1e-12
    speck = gaussian_filter(rng.standard_normal((ny, nx)), 1.5)
    speck /= np.abs(speck).max() + 1e-12
    yy = np.arange(ny)[:, None] * spec.texel_m
    xx = np.arange(nx)[None, :] * spec.texel_m
    warp = gaussian_filter(rng.standard_normal((ny, nx)), 25.0)
    warp /= np.abs(warp).max() + 1e-12
    grain = np.sin(2 * np.pi * (yy / 0.011 + 0.6 * warp + 0.02 * xx / 0.05))
    shade = spec.grain_contrast * (0.3 * grain + 0.8 * blotch + 0.4 * speck)
    tex = np.asarray(spec.base_rgb, dtype=np.float64)[None, None, :] + shade[..., None] * np.array([1.0, 0.85, 0.7])
    tex = np.clip(tex + 0.5, 0, 255).astype(np.uint8)
    tex.setflags(write=False)
    return tex


def table_mesh(spec: TableSpec) -> o3d.geometry.TriangleMesh:
    """The table box in ``base``: top face at z = 0."""
    box = o3d.geometry.TriangleMesh.create_box(spec.size_xy[0], spec.size_xy[1], spec.thickness)
    box.translate((spec.center_xy[0] - spec.size_xy[0] / 2, spec.center_xy[1] - spec.size_xy[1] / 2, -spec.thickness))
    return box


class RenderScene:
    """The static geometry of one world state, with its ray-casting BVH built once.

    ``obj`` stands at ``T_base_object`` (object frame -> base); the table is optional so a test can render
    an object alone.
    """

    def __init__(self, obj: SimObject | None, T_base_object: np.ndarray | None = None, *,
                 table: TableSpec | None = TableSpec(), lighting: Lighting = Lighting(),
                 extras: tuple[SceneBox, ...] = ()):
        self.obj = obj
        self.table = table
        self.extras = tuple(extras)
        self.extra_gids: dict[int, SceneBox] = {}
        self.lighting = lighting
        self.T_base_object = check_transform(np.eye(4) if T_base_object is None else T_base_object, "T_base_object")
        self.scene = o3d.t.geometry.RaycastingScene()
        self.object_gid = -1
        self.table_gid = -1
        if obj is not None:
            V = obj.vertices @ self.T_base_object[:3, :3].T + self.T_base_object[:3, 3]
            gid = self.scene.add_triangles(o3d.core.Tensor(V.astype(np.float32)),
                                           o3d.core.Tensor(obj.triangles.astype(np.uint32)))
            self.object_gid = int(gid)
        if table is not None:
            gid = self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(table_mesh(table)))
            self.table_gid = int(gid)
        for box in self.extras:
            gid = self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(box.mesh()))
            self.extra_gids[int(gid)] = box
        # Open3D commits (builds the BVH) lazily on the first query; do it here, once, so frames rendered
        # from several threads never race on it
        self.scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 0, 0, 0, 1]], dtype=np.float32)))


@dataclass
class RenderResult:
    """One rendered frame. ``labels`` and ``depth_true`` are ground truth, for evaluation."""

    color: np.ndarray  # uint8 (H, W, 3)
    depth: np.ndarray  # uint16 (H, W), metres = depth * depth_scale, 0 = no data
    labels: np.ndarray  # uint8 (H, W): LABEL_NONE, LABEL_TABLE, LABEL_OBJECT (before dropouts)
    depth_true: np.ndarray  # float32 (H, W) metres, exact ray-cast z-depth, 0 = no hit
    depth_scale: float = 0.001
    info: dict = field(default_factory=dict)


@lru_cache(maxsize=8)
def _camera_rays(width: int, height: int, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """Ray directions in the camera frame, (H*W, 3) float32 with z = 1, read-only."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    d = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1).reshape(-1, 3).astype(np.float32)
    d.setflags(write=False)
    return d


@njit(cache=True, nogil=True)
def _compose(t_hit, gids, prims, bary, normals, dirs, origin, obj_gid, tab_gid, mode, tri_uvs, tex, tris, vcols,
             flat_rgb, albedo_in, table_tex, table_x0, table_y0, texel, light, ambient, diffuse, bg,
             color_out, labels_out, depth_out):  # pragma: no cover - compiled
    """Per-pixel shading, one pass over the ray-cast answers (numba: ~5 ms instead of ~40 ms of numpy).

    mode 0: object textured (single texture, bilinear); 1: vertex colours; 2: flat; 3: albedo given.
    Normals are flipped to face the camera (meshes are not always consistently oriented).
    """
    n = t_hit.shape[0]
    th, tw = tex.shape[0], tex.shape[1]
    rows, cols = table_tex.shape[0], table_tex.shape[1]
    for i in range(n):
        t = t_hit[i]
        if not np.isfinite(t):
            labels_out[i] = 0
            depth_out[i] = 0.0
            for c in range(3):
                color_out[i, c] = bg[c]
            continue
        depth_out[i] = t
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if nx * dx + ny * dy + nz * dz > 0:
            nx, ny, nz = -nx, -ny, -nz
        lam = nx * light[0] + ny * light[1] + nz * light[2]
        k = ambient + diffuse * (lam if lam > 0 else 0.0)
        r = g = b = 0.0
        gid = gids[i]
        if gid == obj_gid:
            labels_out[i] = 2
            p = prims[i]
            u = bary[i, 0]
            v = bary[i, 1]
            w0 = 1.0 - u - v
            if mode == 0:
                su = w0 * tri_uvs[p, 0, 0] + u * tri_uvs[p, 1, 0] + v * tri_uvs[p, 2, 0]
                sv = w0 * tri_uvs[p, 0, 1] + u * tri_uvs[p, 1, 1] + v * tri_uvs[p, 2, 1]
                if su < 0.0 or su > 1.0:  # repeat outside [0, 1], clamp to the edge inside (atlases)
                    su -= np.floor(su)
                if sv < 0.0 or sv > 1.0:
                    sv -= np.floor(sv)
                x = su * tw - 0.5
                y = (1.0 - sv) * th - 0.5
                x0 = int(np.floor(x))
                y0 = int(np.floor(y))
                fx = x - x0
                fy = y - y0
                x1 = min(max(x0 + 1, 0), tw - 1)
                y1 = min(max(y0 + 1, 0), th - 1)
                x0 = min(max(x0, 0), tw - 1)
                y0 = min(max(y0, 0), th - 1)
                a00 = (1 - fx) * (1 - fy)
                a01 = fx * (1 - fy)
                a10 = (1 - fx) * fy
                a11 = fx * fy
                r = a00 * tex[y0, x0, 0] + a01 * tex[y0, x1, 0] + a10 * tex[y1, x0, 0] + a11 * tex[y1, x1, 0]
                g = a00 * tex[y0, x0, 1] + a01 * tex[y0, x1, 1] + a10 * tex[y1, x0, 1] + a11 * tex[y1, x1, 1]
                b = a00 * tex[y0, x0, 2] + a01 * tex[y0, x1, 2] + a10 * tex[y1, x0, 2] + a11 * tex[y1, x1, 2]
            elif mode == 1:
                i0, i1, i2 = tris[p, 0], tris[p, 1], tris[p, 2]
                r = 255.0 * (w0 * vcols[i0, 0] + u * vcols[i1, 0] + v * vcols[i2, 0])
                g = 255.0 * (w0 * vcols[i0, 1] + u * vcols[i1, 1] + v * vcols[i2, 1])
                b = 255.0 * (w0 * vcols[i0, 2] + u * vcols[i1, 2] + v * vcols[i2, 2])
            elif mode == 2:
                r, g, b = flat_rgb[0], flat_rgb[1], flat_rgb[2]
            else:
                r, g, b = albedo_in[i, 0], albedo_in[i, 1], albedo_in[i, 2]
        elif gid == tab_gid:
            labels_out[i] = 1
            px = origin[0] + t * dx
            py = origin[1] + t * dy
            col = int((px - table_x0) / texel)
            row = int((py - table_y0) / texel)
            col = min(max(col, 0), cols - 1)
            row = min(max(row, 0), rows - 1)
            r, g, b = table_tex[row, col, 0], table_tex[row, col, 1], table_tex[row, col, 2]
        else:
            labels_out[i] = 0
        color_out[i, 0] = min(max(r * k + 0.5, 0.0), 255.0)
        color_out[i, 1] = min(max(g * k + 0.5, 0.0), 255.0)
        color_out[i, 2] = min(max(b * k + 0.5, 0.0), 255.0)


_EMPTY_UVS = np.zeros((1, 3, 2), dtype=np.float32)
_EMPTY_TEX = np.zeros((1, 1, 3), dtype=np.uint8)
_EMPTY_TRIS = np.zeros((1, 3), dtype=np.int32)
_EMPTY_VCOLS = np.zeros((1, 3), dtype=np.float32)
_EMPTY_ALBEDO = np.zeros((1, 3), dtype=np.float32)


def _ro(a: np.ndarray, dtype: type) -> np.ndarray:
    """C-contiguous, read-only view of ``a`` as ``dtype``: every call of the numba kernel then has one
    signature (numba compiles and caches one specialisation per dtype/layout/writability)."""
    out = np.ascontiguousarray(a, dtype=dtype)
    if out.flags.writeable:
        out = out.view()
        out.setflags(write=False)
    return out


def _object_pixel_rect(scene: RenderScene, T: np.ndarray, K: Intrinsics) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (u0, u1, v0, v1) that contains the object's projected bounding box, or None when
    the box reaches behind the camera (then every ray must be cast)."""
    lo, hi = scene.obj.vertices.min(axis=0), scene.obj.vertices.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    p_base = corners @ scene.T_base_object[:3, :3].T + scene.T_base_object[:3, 3]
    p_cam = (p_base - T[:3, 3]) @ T[:3, :3]
    if np.any(p_cam[:, 2] <= 1e-3):
        return None
    u = K.fx * p_cam[:, 0] / p_cam[:, 2] + K.cx
    v = K.fy * p_cam[:, 1] / p_cam[:, 2] + K.cy
    return (max(int(np.floor(u.min())) - 2, 0), min(int(np.ceil(u.max())) + 2, K.width - 1),
            max(int(np.floor(v.min())) - 2, 0), min(int(np.ceil(v.max())) + 2, K.height - 1))


def _cast(scene: RenderScene, T: np.ndarray, dirs: np.ndarray, K: Intrinsics, full_cast: bool = False
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t_hit, geometry ids, primitive ids, barycentrics, normals) per pixel.

    Ray casting is most of a frame's cost, and most rays hit the table top: those that hit it inside its
    rectangle and do not pass through the object's projected bounding box cannot hit anything else, so
    they are intersected analytically with z = 0 and only the rest go through the BVH.
    """
    n = dirs.shape[0]
    origin = T[:3, 3].astype(np.float32)
    cast = np.ones(n, dtype=bool)
    table_hit = None
    # extra geometry can hide the table: then every ray goes through the BVH
    if scene.table is not None and origin[2] > 1e-6 and not full_cast and not scene.extras:
        dz = dirs[:, 2]
        down = dz < -1e-9
        t = np.full(n, np.inf, dtype=np.float32)
        t[down] = -origin[2] / dz[down]
        with np.errstate(invalid="ignore"):  # inf * 0 for rays that never come down: not table hits anyway
            px = origin[0] + t * dirs[:, 0]
            py = origin[1] + t * dirs[:, 1]
        spec = scene.table
        table_hit = (down & (np.abs(px - spec.center_xy[0]) < spec.size_xy[0] / 2 - 1e-6)
                     & (np.abs(py - spec.center_xy[1]) < spec.size_xy[1] / 2 - 1e-6))
        cast = ~table_hit
        if scene.obj is not None:
            rect = _object_pixel_rect(scene, T, K)
            if rect is None:
                cast[:] = True
            else:
                u0, u1, v0, v1 = rect
                cast.reshape(K.height, K.width)[v0:v1 + 1, u0:u1 + 1] = True
    if cast.all():
        rays = np.empty((n, 6), dtype=np.float32)
        rays[:, :3] = origin
        rays[:, 3:] = dirs
        ans = scene.scene.cast_rays(o3d.core.Tensor(rays))
        return (ans["t_hit"].numpy(), ans["geometry_ids"].numpy(), ans["primitive_ids"].numpy(),
                ans["primitive_uvs"].numpy(), ans["primitive_normals"].numpy())
    idx = np.flatnonzero(cast)
    analytic = ~cast
    t_hit = np.full(n, np.inf, dtype=np.float32)
    gids = np.full(n, o3d.t.geometry.RaycastingScene.INVALID_ID, dtype=np.uint32)
    prims = np.zeros(n, dtype=np.uint32)
    bary = np.zeros((n, 2), dtype=np.float32)
    normals = np.zeros((n, 3), dtype=np.float32)
    t_hit[analytic] = t[analytic]
    gids[analytic] = scene.table_gid
    normals[analytic, 2] = 1.0
    if idx.size:
        rays = np.empty((idx.size, 6), dtype=np.float32)
        rays[:, :3] = origin
        rays[:, 3:] = dirs[idx]
        ans = scene.scene.cast_rays(o3d.core.Tensor(rays))
        t_hit[idx] = ans["t_hit"].numpy()
        gids[idx] = ans["geometry_ids"].numpy()
        prims[idx] = ans["primitive_ids"].numpy()
        bary[idx] = ans["primitive_uvs"].numpy()
        normals[idx] = ans["primitive_normals"].numpy()
    return t_hit, gids, prims, bary, normals


def _shade_extras(scene: RenderScene, gids: np.ndarray, normals: np.ndarray, dirs: np.ndarray,
                  light: np.ndarray, color: np.ndarray, labels: np.ndarray) -> None:
    """Flat Lambert shading and ``LABEL_EXTRA`` for pixels that hit extra boxes (the compiled pass leaves
    them black and unlabelled)."""
    for gid, box in scene.extra_gids.items():
        sel = np.flatnonzero(gids == gid)
        if sel.size == 0:
            continue
        n = normals[sel].astype(np.float64)
        flip = np.einsum("ij,ij->i", n, dirs[sel]) > 0
        n[flip] = -n[flip]
        k = scene.lighting.ambient + scene.lighting.diffuse * np.clip(n @ light, 0.0, None)
        color[sel] = np.clip(np.outer(k, box.rgb) + 0.5, 0, 255).astype(np.uint8)
        labels[sel] = LABEL_EXTRA


def render(scene: RenderScene, T_base_camera: np.ndarray, intrinsics: Intrinsics, *,
           noise: D435Noise | None, rng: np.random.Generator | None = None, full_cast: bool = False) -> RenderResult:
    """Render colour, depth and labels of ``scene`` from a camera at ``T_base_camera`` (optical frame).

    With ``noise`` the D435 model is applied (drawing from ``rng``, required then); without it the
    depth is the exact ray-cast depth quantised to 1 mm, and the colour the shaded albedo.
    ``full_cast`` sends every ray through the BVH instead of intersecting plain table rays analytically
    (same result, slower; for verification).
    """
    T = check_transform(T_base_camera, "T_base_camera")
    w, h = int(intrinsics.width), int(intrinsics.height)
    if w <= 0 or h <= 0 or intrinsics.fx <= 0 or intrinsics.fy <= 0:
        raise SimInputError("intrinsics must be positive", code="bad_value", detail=intrinsics.as_dict())
    if noise is not None and rng is None:
        raise SimInputError("a noisy render needs an rng (for reproducibility)", code="bad_value")
    d_cam = _camera_rays(w, h, float(intrinsics.fx), float(intrinsics.fy), float(intrinsics.cx), float(intrinsics.cy))
    R = T[:3, :3].astype(np.float32)
    dirs = d_cam @ R.T
    n = h * w
    t_hit, gids, prims, bary, normals = _cast(scene, T, dirs, intrinsics, full_cast)
    color = np.empty((n, 3), dtype=np.uint8)
    labels = np.empty(n, dtype=np.uint8)
    depth_true = np.empty(n, dtype=np.float32)
    obj = scene.obj
    mode, tri_uvs, tex, tris, vcols, albedo = 2, _EMPTY_UVS, _EMPTY_TEX, _EMPTY_TRIS, _EMPTY_VCOLS, _EMPTY_ALBEDO
    if obj is not None:
        if obj.appearance == "texture" and len(obj.textures) == 1 and not obj.triangle_material_ids.any():
            mode, tri_uvs, tex = 0, obj.triangle_uvs, obj.textures[0]
        elif obj.appearance == "vertex_colors":
            mode, tris, vcols = 1, obj.triangles, obj.vertex_colors
        elif obj.appearance == "texture":  # several texture images: sample them with numpy
            sel = np.flatnonzero(np.isfinite(t_hit) & (gids == scene.object_gid))
            albedo = np.zeros((n, 3), dtype=np.float32)
            albedo[sel] = obj.surface_colors(prims[sel], bary[sel])
            mode = 3
    table = scene.table
    table_tex = table_texture(table) if table is not None else _EMPTY_TEX
    x0 = table.center_xy[0] - table.size_xy[0] / 2 if table is not None else 0.0
    y0 = table.center_xy[1] - table.size_xy[1] / 2 if table is not None else 0.0
    texel = table.texel_m if table is not None else 1.0
    light = np.asarray(scene.lighting.towards_light, dtype=np.float64)
    light /= np.linalg.norm(light)
    _compose(_ro(t_hit, np.float32), _ro(gids, np.uint32), _ro(prims, np.uint32), _ro(bary, np.float32),
             _ro(normals, np.float32), _ro(dirs, np.float32), _ro(T[:3, 3], np.float32),
             int(scene.object_gid), int(scene.table_gid), int(mode), _ro(tri_uvs, np.float32), _ro(tex, np.uint8),
             _ro(tris, np.int32), _ro(vcols, np.float32), _ro(DEFAULT_COLOR, np.float64), _ro(albedo, np.float32),
             _ro(table_tex, np.uint8), float(x0), float(y0), float(texel), _ro(light, np.float64),
             float(scene.lighting.ambient), float(scene.lighting.diffuse), _ro(BACKGROUND_RGB, np.uint8),
             color, labels, depth_true)
    if scene.extra_gids:
        _shade_extras(scene, gids, normals, dirs, light, color, labels)
    depth_true = depth_true.reshape(h, w)
    color = color.reshape(h, w, 3)
    labels = labels.reshape(h, w)
    if noise is not None:
        depth_m, color = apply_d435_noise(depth_true, color, float(intrinsics.fx), noise, rng)
    else:
        depth_m = depth_true
    depth_mm = np.rint(depth_m * 1000.0)
    depth = np.where(depth_mm <= 65535.0, depth_mm, 0.0).astype(np.uint16)
    return RenderResult(color=color, depth=depth, labels=labels, depth_true=depth_true)


def warm_up(obj: SimObject | None) -> None:
    """Compile (or load from numba's on-disk cache) the shading and D435 kernels now, by rendering one noisy
    frame of ``obj`` from above.

    A fresh checkout or image has no compiled kernels yet, and the first frame would wait for numba: seconds on
    an idle machine, more than the camera waits for a frame on a loaded one (the first capture of a demo from
    a fresh clone then failed with a timeout). The twin's service calls this before it says it is ready.
    """
    T_object = np.eye(4)
    T_object[:2, 3] = (0.5, 0.0)
    T_camera = np.eye(4)
    T_camera[:3, :3] = np.diag([1.0, -1.0, -1.0])  # optical z pointing down at the table
    T_camera[:3, 3] = (0.5, 0.0, 0.5)
    render(RenderScene(obj, T_object), T_camera, d435_intrinsics(), noise=D435Noise.calibrated(),
           rng=np.random.default_rng(0))

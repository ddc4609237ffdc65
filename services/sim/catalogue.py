"""The object catalogue: the demo objects and HOPE objects by name, or any user mesh, as a ``SimObject``
in metres, z up.

Every object is brought into one frame (docs/conventions.md, ``object``): metres, the upright axis is
+z and the origin is the centre of the footprint on the table (bottom centre of the axis-aligned bounds).
That way the world can stand any object on the table by giving only its footprint position and yaw.

Appearance is kept next to the mesh (texture images + per-triangle UVs, or vertex colours) so the
renderer can sample the true surface colour at each ray hit; ``gt_points`` gives uniform surface samples
for evaluation against a reconstruction.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from services.sim.demo_files import MESH_FILE
from services.sim.demo_objects import demo_folder, demo_names
from services.sim.errors import SimObjectError

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
#: Colour of a surface that has neither texture nor vertex colours (light grey).
DEFAULT_COLOR = np.array([180, 180, 180], dtype=np.uint8)
#: HOPE meshes are OBJ in centimetres with y along the object's upright axis (shared/data/hope/SOURCES.txt).
HOPE_SCALE = 0.01
HOPE_UP_AXIS = "y"

_AXES = {"x": 0, "y": 1, "z": 2}
#: Folders (``os.pathsep``-separated) whose sub-folders and mesh files are objects by name, after the demo
#: objects and HOPE; the twin's service also loads any mesh inside them by path (``object_roots.py``).
ENV_OBJECT_DIRS = "OBJSCAN_SIM_OBJECT_DIRS"


def hope_root() -> Path:
    """Folder holding the HOPE objects: ``$OBJSCAN_HOPE_DIR`` or ``<repo>/../shared/data/hope``."""
    env = os.environ.get("OBJSCAN_HOPE_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "hope"


def hope_names() -> list[str]:
    """Names of the HOPE objects available on this machine (empty when the data is absent)."""
    root = hope_root()
    if not root.is_dir():
        return []
    return sorted(d.name for d in root.iterdir() if d.is_dir() and _mesh_in_folder(d) is not None)


def object_dirs(env: dict[str, str] | None = None) -> list[Path]:
    """The user's object folders named by ``$OBJSCAN_SIM_OBJECT_DIRS`` (empty entries skipped)."""
    environ = os.environ if env is None else env
    return [Path(d).expanduser() for d in environ.get(ENV_OBJECT_DIRS, "").split(os.pathsep) if d.strip()]


def named_in_folder(folder: Path, name: str) -> Path | None:
    """The object called ``name`` in an object folder: its sub-folder, or a mesh file of that name."""
    candidate = folder / name
    if candidate.is_dir() or (candidate.is_file() and candidate.suffix.lower() in MESH_SUFFIXES):
        return candidate
    return None


def how_to_name_objects(known_hope: list[str] | None = None) -> str:
    """What can be named, for an ``object_not_found`` message: the demo objects, the HOPE objects found on
    this machine, and how to add one's own."""
    hope = hope_names() if known_hope is None else known_hope
    text = f"demo objects: {', '.join(demo_names())}"
    if hope:
        text += f"; HOPE objects: {', '.join(hope)}"
    return (f"{text}; for another object give --object PATH (a mesh file or a folder holding one) or add its "
            f"folder to an object folder listed in ${ENV_OBJECT_DIRS}")


def up_axis_rotation(up_axis: str) -> np.ndarray:
    """Rotation that maps the mesh's ``up_axis`` ("x", "-y", "+z", ...) onto +z (a proper rotation)."""
    key = up_axis.strip().lower()
    sign = -1.0 if key.startswith("-") else 1.0
    key = key.lstrip("+-")
    if key not in _AXES:
        raise SimObjectError(f"up axis must be one of x, y, z with an optional sign, got {up_axis!r}",
                             code="bad_argument", detail={"up_axis": up_axis})
    up = np.zeros(3)
    up[_AXES[key]] = sign
    z = np.array([0.0, 0.0, 1.0])
    if np.allclose(up, z):
        return np.eye(3)
    if np.allclose(up, -z):
        return np.diag([1.0, -1.0, -1.0])  # 180 deg about x
    axis = np.cross(up, z)
    axis /= np.linalg.norm(axis)
    # 90 degrees about `axis` (Rodrigues with sin = 1, cos = 0)
    Kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + Kx + Kx @ Kx


@dataclass(eq=False)
class SimObject:
    """One object of the twin, in its own frame (metres, z up, bottom centre of the footprint at 0).

    ``mesh`` is a private copy: callers may transform it freely. The numpy arrays are shared between
    loads of the same object and read-only.
    """

    name: str
    mesh: o3d.geometry.TriangleMesh
    vertices: np.ndarray  # (V, 3) float64, object frame
    triangles: np.ndarray  # (T, 3) int32
    textures: list[np.ndarray] = field(default_factory=list)  # (H, W, 3) uint8 each
    triangle_uvs: np.ndarray | None = None  # (T, 3, 2) float32, OBJ convention (v = 0 at the image bottom)
    triangle_material_ids: np.ndarray | None = None  # (T,) int32 index into textures, -1 = untextured
    vertex_colors: np.ndarray | None = None  # (V, 3) float32 in [0, 1]
    source: Path | None = None
    scale: float = 1.0
    up_axis: str = "z"
    _areas: np.ndarray | None = field(default=None, repr=False)

    # -- geometry ---------------------------------------------------------------------------------------
    @property
    def extent(self) -> np.ndarray:
        """Size of the axis-aligned bounds (x, y, z) in metres."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)

    @property
    def height(self) -> float:
        """Height above the table when standing upright (m)."""
        return float(self.vertices[:, 2].max())

    @property
    def appearance(self) -> str:
        """"texture", "vertex_colors" or "untextured" (rendered in DEFAULT_COLOR)."""
        if self.triangle_uvs is not None and self.textures:
            return "texture"
        if self.vertex_colors is not None:
            return "vertex_colors"
        return "untextured"

    def triangle_areas(self) -> np.ndarray:
        if self._areas is None:
            v = self.vertices[self.triangles]
            areas = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
            areas.setflags(write=False)
            self._areas = areas
        return self._areas

    def triangle_normals(self) -> np.ndarray:
        """Unit face normals (T, 3) in the object frame (orientation as the file winds them)."""
        v = self.vertices[self.triangles]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)

    @property
    def surface_area(self) -> float:
        return float(self.triangle_areas().sum())

    def sample_surface(self, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``n`` area-uniform surface samples: (points (n,3), triangle ids (n,), barycentrics (n,2)).

        Barycentrics follow Embree/Open3D ``primitive_uvs``: p = (1-u-v)·v0 + u·v1 + v·v2. Our own RNG
        (not Open3D's global one) keeps the samples deterministic for a seed.
        """
        if n <= 0:
            raise SimObjectError("number of samples must be positive", code="bad_argument", detail={"n": n})
        rng = np.random.default_rng(seed)
        areas = self.triangle_areas()
        tri = rng.choice(len(areas), size=n, p=areas / areas.sum())
        r1 = np.sqrt(rng.random(n))
        r2 = rng.random(n)
        u = r1 * (1.0 - r2)
        v = r1 * r2
        t = self.vertices[self.triangles[tri]]
        pts = (1.0 - u - v)[:, None] * t[:, 0] + u[:, None] * t[:, 1] + v[:, None] * t[:, 2]
        return pts, tri, np.column_stack([u, v])

    def gt_points(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` uniform surface samples in the object frame (metres), for evaluation."""
        return self.sample_surface(n, seed)[0]

    def gt_colored_points(self, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Uniform surface samples and their true colours: ((n,3) float64, (n,3) uint8)."""
        pts, tri, bary = self.sample_surface(n, seed)
        return pts, self.surface_colors(tri, bary)

    def gt_point_cloud(self, n: int, seed: int = 0) -> o3d.geometry.PointCloud:
        """Colored, normal-carrying ground-truth cloud in the object frame (Open3D legacy)."""
        from services.registration.api import to_o3d

        pts, tri, bary = self.sample_surface(n, seed)
        return to_o3d(pts, self.surface_colors(tri, bary), self.triangle_normals()[tri])

    # -- appearance -------------------------------------------------------------------------------------
    def surface_colors(self, triangle_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """True surface colour (uint8 RGB) at points given by triangle ids and barycentrics (u, v).

        Textures are sampled bilinearly through the triangle's UVs (OBJ convention: v = 0 is the bottom
        row of the image; clamped at the image edge, repeated outside [0, 1]); vertex colours are interpolated.
        """
        tri = np.asarray(triangle_ids, dtype=np.int64)
        bary = np.asarray(bary, dtype=np.float32)
        n = tri.shape[0]
        if n == 0:
            return np.zeros((0, 3), dtype=np.uint8)
        w = np.empty((n, 3), dtype=np.float32)
        w[:, 1] = bary[:, 0]
        w[:, 2] = bary[:, 1]
        w[:, 0] = 1.0 - bary[:, 0] - bary[:, 1]
        if self.appearance == "texture":
            uv = np.einsum("nk,nkj->nj", w, self.triangle_uvs[tri])
            out = np.empty((n, 3), dtype=np.uint8)
            mats = (self.triangle_material_ids[tri] if self.triangle_material_ids is not None
                    else np.zeros(n, dtype=np.int32))
            for m in np.unique(mats):
                sel = mats == m
                tex = self.textures[int(m)] if 0 <= m < len(self.textures) else None
                out[sel] = DEFAULT_COLOR if tex is None or tex.size == 0 else _bilinear(tex, uv[sel])
            return out
        if self.appearance == "vertex_colors":
            c = np.einsum("nk,nkj->nj", w, self.vertex_colors[self.triangles[tri]])
            return np.clip(c * 255.0 + 0.5, 0, 255).astype(np.uint8)
        return np.broadcast_to(DEFAULT_COLOR, (n, 3)).copy()

    def copy(self) -> SimObject:
        """Same object with its own mesh (arrays stay shared and read-only)."""
        return SimObject(self.name, o3d.geometry.TriangleMesh(self.mesh), self.vertices, self.triangles,
                         self.textures, self.triangle_uvs, self.triangle_material_ids, self.vertex_colors,
                         self.source, self.scale, self.up_axis, self._areas)


def _bilinear(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear texture lookup; uv in OBJ convention (v up). Coordinates outside [0, 1] repeat, texels are
    clamped at the image edge (atlases must not bleed across their border)."""
    h, w = tex.shape[:2]
    u = np.where((uv[:, 0] < 0) | (uv[:, 0] > 1), uv[:, 0] - np.floor(uv[:, 0]), uv[:, 0])
    v = np.where((uv[:, 1] < 0) | (uv[:, 1] > 1), uv[:, 1] - np.floor(uv[:, 1]), uv[:, 1])
    x = u * w - 0.5
    y = (1.0 - v) * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    x1 = np.clip(x0 + 1, 0, w - 1)
    y1 = np.clip(y0 + 1, 0, h - 1)
    x0 = np.clip(x0, 0, w - 1)
    y0 = np.clip(y0, 0, h - 1)
    t = tex.astype(np.float32, copy=False) if tex.dtype == np.float32 else tex
    c = ((t[y0, x0] * (1 - fx) + t[y0, x1] * fx) * (1 - fy)
         + (t[y1, x0] * (1 - fx) + t[y1, x1] * fx) * fy)
    return np.clip(c + 0.5, 0, 255).astype(np.uint8)


# -- loading --------------------------------------------------------------------------------------------

_CACHE: dict[tuple[str, float, str], SimObject] = {}
_CACHE_LOCK = threading.Lock()


def _mesh_in_folder(folder: Path) -> Path | None:
    for pattern in ("textured.obj", f"{folder.name}.obj", "*.obj", "*.ply", "*.glb", "*.stl"):
        found = sorted(p for p in folder.glob(pattern) if p.is_file())
        if found:
            return found[0]
    return None


def resolve_object(name_or_path: str) -> tuple[str, Path, bool]:
    """(name, mesh path, is_hope) for a demo object's name, a HOPE name, an object in a folder of
    ``$OBJSCAN_SIM_OBJECT_DIRS`` (by name), a mesh file or a folder holding one."""
    text = str(name_or_path).strip()
    if not text:
        raise SimObjectError(f"object name is empty ({how_to_name_objects()})", code="object_not_found")
    path = Path(text).expanduser()
    root = hope_root()
    bare = len(path.parts) == 1 and text not in (".", "..")
    # a bare name is a demo object's or a HOPE name first (a folder of that name where the process runs does
    # not shadow it)
    demo = demo_folder(text) if bare else None
    if demo is not None:
        return text, demo / MESH_FILE, False
    if path.suffix.lower() not in MESH_SUFFIXES and (bare or not path.is_dir()) and (root / text).is_dir():
        mesh = _mesh_in_folder(root / text)
        if mesh is None:
            raise SimObjectError(f"HOPE object {text!r} has no mesh in {root / text}", code="object_not_found")
        return text, mesh, True
    if bare:
        for folder in object_dirs():
            found = named_in_folder(folder, text)
            if found is not None:
                path = found
                break
    if path.is_dir():
        mesh = _mesh_in_folder(path)
        if mesh is None:
            raise SimObjectError(f"no mesh ({', '.join(MESH_SUFFIXES)}) in folder {path}",
                                 code="object_not_found", detail={"path": str(path)})
        return path.name, mesh, False
    if path.is_file():
        if path.suffix.lower() not in MESH_SUFFIXES:
            raise SimObjectError(f"{path} is not a mesh file (expected {', '.join(MESH_SUFFIXES)})",
                                 code="bad_mesh", detail={"path": str(path)})
        return path.stem, path, False
    known = hope_names()
    raise SimObjectError(f"unknown object {text!r}: not an object name nor an existing mesh file or folder "
                         f"({how_to_name_objects(known)})", code="object_not_found",
                         detail={"name": text, "demo": demo_names(), "known": known})


def load_object(name_or_path: str, *, scale: float | None = None, up_axis: str | None = None) -> SimObject:
    """Load a demo object (``carton``, ``can``, ``flat_box``), a HOPE object by name (``milk``, ...) or any
    mesh file (OBJ/PLY/STL/GLB, textured or vertex coloured), in metres with z up and the bottom centre of
    the footprint at the origin.

    ``scale`` multiplies the file's units into metres (HOPE default 0.01, otherwise 1.0); ``up_axis`` names
    the file's upright axis ("y", "-z", ...; HOPE default "y", otherwise "z"). Parsed meshes are cached;
    each call returns an object with its own ``mesh`` copy. Raises ``SimObjectError`` when the name is
    unknown, the file is missing, or the mesh is unreadable, empty, non-finite or flat.
    """
    if str(name_or_path).strip() == CHARUCO_OBJECT:
        return charuco_object()
    name, path, is_hope = resolve_object(name_or_path)
    if scale is None:
        scale = HOPE_SCALE if is_hope else 1.0
    if up_axis is None:
        up_axis = HOPE_UP_AXIS if is_hope else "z"
    if not np.isfinite(scale) or scale <= 0:
        raise SimObjectError(f"scale must be a positive number, got {scale}", code="bad_argument",
                             detail={"scale": scale})
    up_axis_rotation(up_axis)  # validate before touching the file
    key = (str(path.resolve()), float(scale), up_axis.strip().lower())
    with _CACHE_LOCK:
        cached = _CACHE.get(key)
    if cached is None:
        cached = _parse(name, path, float(scale), up_axis)
        with _CACHE_LOCK:
            _CACHE.setdefault(key, cached)
    return cached.copy()


#: The built-in calibration target: ``load_object("charuco")`` is the hand-eye board as a thin plate.
CHARUCO_OBJECT = "charuco"


def charuco_object() -> SimObject:
    """The ChArUco board of ``services.calibration.board.CharucoSpec()`` as a textured plate (its print on
    top), so the twin renders exactly the board the hand-eye procedure looks for."""
    from services.calibration.board import CharucoSpec, board_plate_mesh

    spec = CharucoSpec()
    V, F, uvs, mats = board_plate_mesh(spec)
    tex = spec.image()
    legacy = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    legacy.compute_vertex_normals()
    for a in (V, F, tex, uvs, mats):
        a.setflags(write=False)
    return SimObject(name=CHARUCO_OBJECT, mesh=legacy, vertices=V, triangles=F, textures=[tex], triangle_uvs=uvs,
                     triangle_material_ids=mats, scale=1.0, up_axis="z")


def _parse(name: str, path: Path, scale: float, up_axis: str) -> SimObject:
    try:
        mesh = o3d.io.read_triangle_mesh(str(path), enable_post_processing=False, print_progress=False)
    except Exception as exc:  # noqa: BLE001 - Open3D raises assorted RuntimeErrors on garbage
        raise SimObjectError(f"cannot read mesh {path}: {exc}", code="bad_mesh", detail={"path": str(path)}) from None
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.triangles, dtype=np.int64)
    if V.shape[0] < 3 or F.shape[0] < 1:
        raise SimObjectError(f"{path} is not a readable triangle mesh ({V.shape[0]} vertices, {F.shape[0]} "
                             "triangles)", code="bad_mesh", detail={"path": str(path)})
    if not np.all(np.isfinite(V)):
        raise SimObjectError(f"{path} has NaN or infinite vertices", code="bad_mesh", detail={"path": str(path)})
    if F.min() < 0 or F.max() >= V.shape[0]:
        raise SimObjectError(f"{path} has triangle indices out of range", code="bad_mesh",
                             detail={"path": str(path)})

    R = up_axis_rotation(up_axis)
    V = (V * scale) @ R.T
    lo, hi = V.min(axis=0), V.max(axis=0)
    if np.any(hi - lo < 1e-4):
        raise SimObjectError(f"{path} is flat or degenerate after scaling (extent {np.round(hi - lo, 5).tolist()} m)",
                             code="bad_mesh", detail={"path": str(path)})
    V -= np.array([(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, lo[2]])

    # Open3D stores texture images bottom row first (so that row = v * H); keep them as the file has
    # them (top row first) and sample with row = (1 - v) * H, the OBJ convention.
    # Materials without a texture map show up as empty images; drop them and renumber the material ids
    # (-1 = untextured triangle, drawn in DEFAULT_COLOR).
    o3d_textures = list(mesh.textures)
    valid = [np.asarray(t).ndim == 3 and np.asarray(t).size > 0 for t in o3d_textures]
    textures = [np.ascontiguousarray(np.asarray(t)[::-1, :, :3]).astype(np.uint8)
                for t, ok in zip(o3d_textures, valid, strict=True) if ok]
    uvs = None
    mats = None
    if mesh.has_triangle_uvs() and len(mesh.triangle_uvs) == 3 * F.shape[0] and textures:
        uvs = np.asarray(mesh.triangle_uvs, dtype=np.float32).reshape(-1, 3, 2)
        if not np.all(np.isfinite(uvs)):
            raise SimObjectError(f"{path} has NaN texture coordinates", code="bad_mesh", detail={"path": str(path)})
        raw = (np.asarray(mesh.triangle_material_ids, dtype=np.int64) if mesh.has_triangle_material_ids()
               else np.zeros(F.shape[0], dtype=np.int64))
        renumber = np.cumsum(valid) - 1
        ok = (raw >= 0) & (raw < len(valid))
        mats = np.full(F.shape[0], -1, dtype=np.int32)
        mats[ok] = np.where(np.asarray(valid)[raw[ok]], renumber[raw[ok]], -1)
        if len(textures) == 1 and len(valid) == 1:
            mats[:] = 0  # one material, one texture: whatever ids the loader wrote
    else:
        textures = []
    vcols = None
    if mesh.has_vertex_colors():
        vcols = np.clip(np.asarray(mesh.vertex_colors, dtype=np.float32), 0.0, 1.0)

    legacy = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    if uvs is not None:
        legacy.triangle_uvs = o3d.utility.Vector2dVector(uvs.reshape(-1, 2).astype(np.float64))
        legacy.textures = [o3d.geometry.Image(np.ascontiguousarray(t[::-1])) for t in textures]
        legacy.triangle_material_ids = o3d.utility.IntVector(mats.tolist())
    if vcols is not None:
        legacy.vertex_colors = o3d.utility.Vector3dVector(vcols.astype(np.float64))
    legacy.compute_vertex_normals()

    arrays = [V, F.astype(np.int32)] + textures + [a for a in (uvs, mats, vcols) if a is not None]
    for a in arrays:
        a.setflags(write=False)
    return SimObject(name=name, mesh=legacy, vertices=arrays[0], triangles=arrays[1], textures=textures,
                     triangle_uvs=uvs, triangle_material_ids=mats, vertex_colors=vcols, source=path,
                     scale=scale, up_axis=up_axis)

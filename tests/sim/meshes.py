"""Test meshes with known geometry and appearance, written to a temporary folder by the tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

# texture quadrants as they appear in the image file (row 0 at the top)
TOP_LEFT = (220, 30, 30)
TOP_RIGHT = (30, 200, 40)
BOTTOM_LEFT = (30, 40, 210)
BOTTOM_RIGHT = (240, 240, 240)


def quadrant_texture(size: int = 64) -> np.ndarray:
    img = np.zeros((size, size, 3), dtype=np.uint8)
    h = size // 2
    img[:h, :h] = TOP_LEFT
    img[:h, h:] = TOP_RIGHT
    img[h:, :h] = BOTTOM_LEFT
    img[h:, h:] = BOTTOM_RIGHT
    return img


def box_faces(size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cube [0, size]^3 as 6 quads of 4 own vertices each: (vertices (24,3), uvs (24,2), quads (6,4)).

    Every face maps the whole texture with u growing to the right and v growing up *as seen from outside*
    with z up (for the top/bottom faces: as seen with +x up), so a camera looking at a face with the
    world's up appearing up sees the texture file upright.
    """
    s = size
    # (origin corner, right direction, up direction) seen from outside
    faces = [
        ((0, s, 0), (0, -1, 0), (0, 0, 1)),  # -x face, seen from -x: right = -y
        ((s, 0, 0), (0, 1, 0), (0, 0, 1)),  # +x face
        ((0, 0, 0), (1, 0, 0), (0, 0, 1)),  # -y face
        ((s, s, 0), (-1, 0, 0), (0, 0, 1)),  # +y face
        ((0, s, s), (0, -1, 0), (1, 0, 0)),  # +z face seen from above with +x up: right = -y
        ((0, 0, 0), (0, 1, 0), (1, 0, 0)),  # -z face seen from below with +x up: right = +y
    ]
    V, UV, Q = [], [], []
    for origin, right, up in faces:
        o, r, u = np.array(origin, float), np.array(right, float) * s, np.array(up, float) * s
        base = len(V)
        V += [o, o + r, o + r + u, o + u]
        UV += [(0, 0), (1, 0), (1, 1), (0, 1)]
        Q.append([base, base + 1, base + 2, base + 3])
    return np.array(V), np.array(UV, float), np.array(Q)


def write_textured_box_obj(folder: Path, size: float = 0.1, name: str = "qbox") -> Path:
    """OBJ + MTL + PNG of a cube whose every face shows the quadrant texture; returns the OBJ path."""
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(quadrant_texture()).save(folder / f"{name}.png")
    (folder / f"{name}.mtl").write_text(f"newmtl tex\nmap_Kd {name}.png\n")
    V, UV, Q = box_faces(size)
    lines = [f"mtllib {name}.mtl"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in V]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in UV]
    lines.append("usemtl tex")
    for a, b, c, d in Q + 1:
        lines.append(f"f {a}/{a} {b}/{b} {c}/{c}")
        lines.append(f"f {a}/{a} {c}/{c} {d}/{d}")
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def write_textured_box_glb(folder: Path, size: float = 0.1, name: str = "qbox") -> Path:
    """The same textured cube as a binary glTF (through trimesh)."""
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    V, UV, Q = box_faces(size)
    F = np.vstack([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])
    visual = trimesh.visual.TextureVisuals(uv=UV, image=Image.fromarray(quadrant_texture()))
    mesh = trimesh.Trimesh(vertices=V, faces=F, visual=visual, process=False)
    path = folder / f"{name}.glb"
    mesh.export(path)
    return path


def write_box_ply(folder: Path, extent: tuple[float, float, float], name: str = "box",
                  rgb: tuple[int, int, int] | None = None) -> Path:
    """A box mesh as PLY (optionally vertex-coloured), origin at a corner."""
    import open3d as o3d

    folder.mkdir(parents=True, exist_ok=True)
    box = o3d.geometry.TriangleMesh.create_box(*extent)
    if rgb is not None:
        box.paint_uniform_color(np.asarray(rgb, float) / 255.0)
    path = folder / f"{name}.ply"
    o3d.io.write_triangle_mesh(str(path), box, write_ascii=True)
    return path

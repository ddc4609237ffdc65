"""The files an export writes: meshes for viewers (OBJ+MTL+PNG, GLB, PLY, STL) and simulation assets (MJCF, URDF).

Every file is in the object frame (``frame.py``), metres. The simulation assets reference the visual OBJ
and the convex parts (``collision/<name>_part_KK.stl``) by relative paths, so the folder loads as it is
wherever it is copied. Files are written to a temporary name and renamed (``common.atomic``).
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
from PIL import Image

from common.atomic import atomic_path
from services.export.collision import CollisionParts
from services.export.errors import ExportError
from services.export.physics import Inertial
from services.export.texture import TexturedMesh

FORMATS = ("mjcf", "urdf", "glb", "obj", "ply", "stl")


def _write_bytes(path: Path, data: bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    return path


def _write_text(path: Path, text: str) -> Path:
    return _write_bytes(path, text.encode("utf-8"))


def to_trimesh(mesh: TexturedMesh):  # noqa: ANN201 - trimesh is imported lazily
    """A trimesh with the texture (vertices split where the atlas has seams) or the vertex colours."""
    import trimesh

    if not mesh.textured:
        return trimesh.Trimesh(mesh.vertices, mesh.triangles, vertex_colors=mesh.vertex_colors, process=False)
    corners = mesh.triangles.reshape(-1)
    uv = mesh.triangle_uvs.reshape(-1, 2).astype(np.float64)
    key = np.column_stack([corners.astype(np.float64), np.round(uv * 1e6)])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    vertices = mesh.vertices[corners[first]]
    visual = trimesh.visual.TextureVisuals(uv=uv[first], image=Image.fromarray(mesh.albedo))
    return trimesh.Trimesh(vertices, inverse.reshape(-1, 3), visual=visual, process=False)


def write_obj(mesh: TexturedMesh, out: Path, name: str) -> Path:
    """``name.obj`` (+ ``name.mtl`` and ``name.png`` when textured); vertex colours as ``v x y z r g b``."""
    import trimesh

    tm = to_trimesh(mesh)
    text, files = trimesh.exchange.obj.export_obj(tm, include_texture=True, include_color=not mesh.textured,
                                                  mtl_name=f"{name}.mtl", return_texture=True)
    for fname, data in files.items():
        if fname.endswith(".mtl"):
            data = data.replace(b"map_Kd material_0.png", f"map_Kd {name}.png".encode())
            _write_bytes(out / f"{name}.mtl", data)
        elif fname.lower().endswith(".png"):
            _write_bytes(out / f"{name}.png", data)  # trimesh's encoding of the albedo: not encoded twice
    return _write_text(out / f"{name}.obj", text)


def write_glb(mesh: TexturedMesh, out: Path, name: str) -> Path:
    """Binary glTF with the albedo embedded (viewers, Blender, web)."""
    return _write_bytes(out / f"{name}.glb", to_trimesh(mesh).export(file_type="glb"))


def write_ply(mesh: TexturedMesh, out: Path, name: str) -> Path:
    """Binary PLY mesh with vertex colours (MeshLab, Open3D)."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.triangles, vertex_colors=mesh.vertex_colors, process=False)
    return _write_bytes(out / f"{name}.ply", tm.export(file_type="ply"))


def write_stl(mesh: TexturedMesh, out: Path, name: str) -> Path:
    """Binary STL (geometry only: CAD, 3D printing)."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.triangles, process=False)
    return _write_bytes(out / f"{name}.stl", tm.export(file_type="stl"))


def write_parts(parts: CollisionParts, out: Path, name: str) -> list[Path]:
    """One binary STL per convex part under ``collision/``."""
    import trimesh

    paths = []
    for k in range(len(parts.parts)):
        v, t = parts.hull_triangles(k)
        tm = trimesh.Trimesh(v, t, process=False)
        paths.append(_write_bytes(out / "collision" / f"{name}_part_{k:02d}.stl", tm.export(file_type="stl")))
    return paths


def _f(x: float) -> str:
    return f"{float(x):.9g}"


def mjcf_text(name: str, visual_obj: str, texture_png: str | None, part_files: list[str], inertial: Inertial,
              friction: float = 0.8) -> str:
    """The MJCF document: one free body, the visual mesh (no contacts) and the convex parts, explicit inertia."""
    I = inertial.inertia
    q = quoteattr
    lines = [f"<mujoco model={q(name)}>",
             '  <compiler angle="radian" meshdir="." texturedir="." inertiafromgeom="false"/>',
             "  <asset>"]
    if texture_png:
        lines += [f"    <texture name={q(name + '_albedo')} type=\"2d\" file={q(texture_png)}/>",
                  f"    <material name={q(name + '_material')} texture={q(name + '_albedo')}/>"]
    lines.append(f"    <mesh name={q(name + '_visual')} file={q(visual_obj)}/>")
    for k, f in enumerate(part_files):
        lines.append(f"    <mesh name={q(f'{name}_part_{k:02d}')} file={q(f)}/>")
    lines += ["  </asset>", "  <worldbody>", f"    <body name={q(name)} pos=\"0 0 0\">",
              f"      <freejoint name={q(name + '_free')}/>",
              f"      <inertial pos=\"{' '.join(_f(c) for c in inertial.com)}\" mass=\"{_f(inertial.mass)}\" "
              f"fullinertia=\"{_f(I[0, 0])} {_f(I[1, 1])} {_f(I[2, 2])} {_f(I[0, 1])} {_f(I[0, 2])} {_f(I[1, 2])}\"/>",
              f"      <geom name={q(name + '_visual')} type=\"mesh\" mesh={q(name + '_visual')} contype=\"0\" "
              f"conaffinity=\"0\" group=\"1\" mass=\"0\""
              + (f" material={q(name + '_material')}" if texture_png else "") + "/>"]
    for k in range(len(part_files)):
        lines.append(f"      <geom name={q(f'{name}_collision_{k:02d}')} type=\"mesh\" "
                     f"mesh={q(f'{name}_part_{k:02d}')} group=\"3\" rgba=\"0.5 0.5 0.5 0\" "
                     f"friction=\"{_f(friction)} 0.005 0.0001\"/>")
    lines += ["    </body>", "  </worldbody>", "</mujoco>", ""]
    return "\n".join(lines)


def urdf_text(name: str, visual_mesh: str, part_files: list[str], inertial: Inertial) -> str:
    """The URDF document: one link with the visual mesh, the convex parts as collisions and the inertial."""
    I = inertial.inertia
    q = quoteattr
    c = " ".join(_f(x) for x in inertial.com)
    lines = ['<?xml version="1.0"?>', f"<robot name={q(name)}>", f"  <link name={q(name)}>",
             "    <inertial>", f"      <origin xyz=\"{c}\" rpy=\"0 0 0\"/>",
             f"      <mass value=\"{_f(inertial.mass)}\"/>",
             f"      <inertia ixx=\"{_f(I[0, 0])}\" ixy=\"{_f(I[0, 1])}\" ixz=\"{_f(I[0, 2])}\" iyy=\"{_f(I[1, 1])}\" "
             f"iyz=\"{_f(I[1, 2])}\" izz=\"{_f(I[2, 2])}\"/>", "    </inertial>",
             f"    <visual name={q(name + '_visual')}>", "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>",
             f"      <geometry><mesh filename={q(visual_mesh)}/></geometry>", "    </visual>"]
    for k, f in enumerate(part_files):
        lines += [f"    <collision name={q(f'{name}_collision_{k:02d}')}>",
                  "      <origin xyz=\"0 0 0\" rpy=\"0 0 0\"/>",
                  f"      <geometry><mesh filename={q(f)}/></geometry>", "    </collision>"]
    lines += ["  </link>", "</robot>", ""]
    return "\n".join(lines)


def _check_formats(formats: tuple[str, ...]) -> None:
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise ExportError(f"unknown export format(s) {unknown}; known: {list(FORMATS)}", code="bad_argument")


def write_meshes(mesh: TexturedMesh, out: Path, name: str, formats: tuple[str, ...] = FORMATS) -> dict[str, list[str]]:
    """The mesh files of ``formats`` (OBJ also when MJCF or URDF need it as their visual); {format: [files]}.

    They need no collision parts: the export writes them while the parts are being made.
    """
    _check_formats(formats)
    out = Path(out)
    files: dict[str, list[str]] = {}
    if "obj" in formats or "mjcf" in formats or "urdf" in formats:
        write_obj(mesh, out, name)
        files["obj"] = [f"{name}.obj"] + ([f"{name}.mtl", f"{name}.png"] if mesh.textured else [])
    for fmt, writer in (("glb", write_glb), ("ply", write_ply), ("stl", write_stl)):
        if fmt in formats:
            files[fmt] = [str(Path(writer(mesh, out, name)).relative_to(out))]
    return files


def write_asset(textured: bool, parts: CollisionParts, inertial: Inertial, out: Path, name: str,
                formats: tuple[str, ...] = FORMATS) -> dict[str, list[str]]:
    """The simulation assets of ``formats`` (MJCF, URDF) and their convex parts, beside the OBJ
    ``write_meshes`` wrote (``textured``: it has the albedo PNG); {format: [files]}."""
    _check_formats(formats)
    out = Path(out)
    files: dict[str, list[str]] = {}
    rel = lambda p: str(Path(p).relative_to(out))  # noqa: E731
    part_files: list[str] = []
    if "mjcf" in formats or "urdf" in formats:
        part_files = [rel(p) for p in write_parts(parts, out, name)]
    if "mjcf" in formats:
        text = mjcf_text(name, f"{name}.obj", f"{name}.png" if textured else None, part_files, inertial)
        files["mjcf"] = [rel(_write_text(out / f"{name}.xml", text))] + part_files
    if "urdf" in formats:
        files["urdf"] = [rel(_write_text(out / f"{name}.urdf", urdf_text(name, f"{name}.obj", part_files, inertial)))] \
            + part_files
    return files


def write_all(mesh: TexturedMesh, parts: CollisionParts, inertial: Inertial, out: Path, name: str,
              formats: tuple[str, ...] = FORMATS) -> dict[str, list[str]]:
    """Write the requested ``formats`` into ``out``; returns {format: [relative file paths]}."""
    files = write_meshes(mesh, out, name, formats)
    return {**files, **write_asset(mesh.textured, parts, inertial, out, name, formats)}

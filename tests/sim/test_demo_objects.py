"""The demo objects ship with the repository, load by name like any mesh, and are what their generator makes.

They are what a fresh clone scans (``scripts/demo.sh``), so they must be present without any data beside the
checkout, be the same bytes on every machine, be groceries the RH-P12-RN can hold, and carry a print that
colour registration can hold on to.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from services.sim import demo_files, demo_objects
from services.sim.catalogue import load_object, resolve_object
from services.sim.demo_files import OBJECTS_DIR
from services.sim.demo_objects import DEMO_OBJECTS, demo_names
from services.sim.errors import SimObjectError
from services.sim.gripper import GripperSpec
from services.sim.object_roots import ObjectRoots
from tests.sim.meshes import write_box_ply

REPO = Path(__file__).resolve().parents[2]


def test_the_committed_files_are_what_the_generator_makes():
    assert demo_objects.differences() == []


def test_a_fresh_process_generates_the_same_bytes(tmp_path):
    """Two generations, in another interpreter with another hash seed, write byte-identical files."""
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    subprocess.run([sys.executable, "-m", "services.sim.demo_objects", "--out", str(tmp_path)], cwd=REPO, env=env,
                   check=True, capture_output=True, timeout=120)
    for name in DEMO_OBJECTS:
        for file_name in (demo_files.MESH_FILE, demo_files.MTL_FILE, demo_files.TEXTURE_FILE):
            assert (tmp_path / name / file_name).read_bytes() == (OBJECTS_DIR / name / file_name).read_bytes(), \
                (name, file_name)
    check = subprocess.run([sys.executable, "-m", "services.sim.demo_objects", "--out", str(tmp_path), "--check"],
                           cwd=REPO, capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stderr
    (tmp_path / "can" / demo_files.TEXTURE_FILE).write_bytes(b"not a png")
    check = subprocess.run([sys.executable, "-m", "services.sim.demo_objects", "--out", str(tmp_path), "--check"],
                           cwd=REPO, capture_output=True, text=True, timeout=120)
    assert check.returncode == 1 and "can" in check.stderr


def test_the_files_are_in_git_so_a_clone_and_git_archive_carry_them():
    listed = subprocess.run(["git", "ls-files", "services/sim/objects", "services/sim/demo_meshes.py",
                             "services/sim/demo_objects.py"], cwd=REPO, capture_output=True, text=True, check=True)
    tracked = set(listed.stdout.split())
    if not tracked:
        pytest.skip("not a git checkout")
    for name in DEMO_OBJECTS:
        for file_name in (demo_files.MESH_FILE, demo_files.MTL_FILE, demo_files.TEXTURE_FILE):
            assert f"services/sim/objects/{name}/{file_name}" in tracked
    assert {"services/sim/demo_meshes.py", "services/sim/demo_objects.py"} <= tracked


@pytest.mark.parametrize("name", list(DEMO_OBJECTS))
def test_a_demo_object_loads_by_name_as_a_grocery_the_gripper_holds(name):
    obj = load_object(name)
    assert obj.name == name and obj.appearance == "texture" and len(obj.textures) == 1
    assert obj.source is not None and obj.source.parent == OBJECTS_DIR / name
    assert (obj.scale, obj.up_axis) == (1.0, "z")
    ext = obj.extent
    stroke = GripperSpec().max_opening
    assert min(ext[0], ext[1]) < stroke - 0.02, ext  # graspable across its narrow side with room to spare
    assert 0.04 <= ext[2] <= 0.25 and max(ext) <= 0.2, ext  # grocery-sized, metres (not cm or mm)
    # closed and outward: the signed volume of the triangles equals the convex hull's (all three are convex)
    v = obj.vertices[obj.triangles]
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0
    from scipy.spatial import ConvexHull
    assert volume == pytest.approx(ConvexHull(obj.vertices).volume, rel=1e-3)
    # the same object by path: a demo object is an ordinary textured OBJ in metres, z up
    by_path = load_object(str(OBJECTS_DIR / name))
    np.testing.assert_array_equal(by_path.vertices, obj.vertices)


@pytest.mark.parametrize("name", list(DEMO_OBJECTS))
def test_a_demo_object_is_printed_all_over(name):
    """Every side seen by the camera has print: strong colour contrast in each 90-degree sector of the side."""
    obj = load_object(name)
    pts, rgb = obj.gt_colored_points(40_000, seed=0)
    side = pts[:, 2] < obj.height * 0.8
    angle = np.degrees(np.arctan2(pts[side, 1], pts[side, 0])) % 360.0
    colors = rgb[side].astype(np.float64)
    for lo in range(0, 360, 90):
        sector = colors[(angle >= lo) & (angle < lo + 90)]
        assert len(sector) > 500
        quantised = {tuple(c) for c in (sector // 32).astype(int)}
        assert len(quantised) >= 6, (name, lo, len(quantised))  # several inks, not one flat colour
        assert sector.std(axis=0).max() > 40, (name, lo)
    # the four quarters differ from each other: a turn changes what the camera sees
    means = [colors[(angle >= lo) & (angle < lo + 90)].mean(axis=0) for lo in range(0, 360, 90)]
    assert min(np.linalg.norm(a - b) for i, a in enumerate(means) for b in means[i + 1:]) > 5


def test_an_unknown_object_names_what_there_is_and_how_to_add_one(tmp_path, monkeypatch):
    monkeypatch.setenv("OBJSCAN_HOPE_DIR", str(tmp_path / "no_hope_here"))
    with pytest.raises(SimObjectError) as exc:
        resolve_object("milk")
    e = exc.value
    assert e.code == "object_not_found"
    for word in (*demo_names(), "--object PATH", "OBJSCAN_SIM_OBJECT_DIRS"):
        assert word in e.message, (word, e.message)
    assert "HOPE objects" not in e.message and e.detail["demo"] == demo_names()

    hope = tmp_path / "hope"
    write_box_ply(hope / "tea_box", (0.05, 0.05, 0.1), name="tea_box")
    monkeypatch.setenv("OBJSCAN_HOPE_DIR", str(hope))
    with pytest.raises(SimObjectError) as exc:
        resolve_object("coffee")
    assert "HOPE objects: tea_box" in exc.value.message and "carton" in exc.value.message


def test_the_twin_answers_the_same_for_absent_and_outside_names_and_lists_the_demo_objects(tmp_path, monkeypatch):
    monkeypatch.setenv("OBJSCAN_HOPE_DIR", str(tmp_path / "hope"))
    roots = ObjectRoots.configured(None, (), env={})
    answers = set()
    for name in ("/etc", "/nonexistent", "etc", "nothing_here", str(tmp_path)):
        with pytest.raises(SimObjectError) as exc:
            roots.check(name)
        answers.add((exc.value.code, exc.value.message.replace(repr(name), "<name>")))
    assert len(answers) == 1
    code, message = answers.pop()
    assert code == "object_not_found" and all(n in message for n in demo_names())
    assert "--object PATH" in message and "OBJSCAN_SIM_OBJECT_DIRS" in message
    for name in demo_names():  # a demo object needs no configuration: by name and by path in its folder
        assert roots.check(name) == name
        assert roots.check(str(OBJECTS_DIR / name / demo_files.MESH_FILE)) == str(
            OBJECTS_DIR / name / demo_files.MESH_FILE)


def test_an_object_folder_serves_its_objects_by_name(tmp_path, monkeypatch):
    """``$OBJSCAN_SIM_OBJECT_DIRS`` adds objects: a sub-folder or a mesh file there is scanned by its name."""
    monkeypatch.setenv("OBJSCAN_HOPE_DIR", str(tmp_path / "hope"))
    shelf = tmp_path / "shelf"
    write_box_ply(shelf / "mug", (0.08, 0.08, 0.1), name="mug")
    jar = write_box_ply(shelf, (0.06, 0.06, 0.09), name="jar")
    monkeypatch.setenv("OBJSCAN_SIM_OBJECT_DIRS", str(shelf))
    assert resolve_object("mug")[:2] == ("mug", shelf / "mug" / "mug.ply")
    assert load_object(jar.name).name == "jar"
    roots = ObjectRoots.configured(None, ())
    assert roots.check("mug") == str(shelf / "mug")
    assert load_object(roots.check("mug")).name == "mug"
    # a flag folder counts too, and a bare name never reaches the service's working directory
    flag_dir = tmp_path / "flag_objects"
    write_box_ply(flag_dir / "kettle", (0.1, 0.1, 0.1), name="kettle")
    monkeypatch.delenv("OBJSCAN_SIM_OBJECT_DIRS")
    monkeypatch.chdir(tmp_path / "shelf")
    roots = ObjectRoots.configured(None, (str(flag_dir),))
    assert roots.check("kettle") == str(flag_dir / "kettle")
    with pytest.raises(SimObjectError) as exc:
        roots.check("mug")  # only a folder of the working directory: not an object folder
    assert exc.value.code == "object_not_found"


def test_the_image_and_the_package_carry_the_demo_objects():
    """The Dockerfile copies the package folder holding them, nothing ignores them, and a wheel includes them."""
    dockerfile = (REPO / "Dockerfile").read_text()
    copied = re.findall(r"^COPY\s+(\S+)\s+\./\1\s*$", dockerfile, flags=re.M)
    assert "services" in copied, copied
    ignore = REPO / ".dockerignore"
    if ignore.exists():
        patterns = [p.strip() for p in ignore.read_text().splitlines() if p.strip() and not p.startswith("#")]
        assert not any(p.strip("/").split("/")[0] in ("services", "objects", "*.obj", "*.png") for p in patterns)
    pyproject = (REPO / "pyproject.toml").read_text()
    assert re.search(r'"services\.sim"\s*=\s*\[[^\]]*"objects/\*/\*"', pyproject), "package-data lacks the objects"


def test_demo_sh_scans_the_demo_object():
    text = (REPO / "scripts" / "demo.sh").read_text()
    assert re.search(r"objscan scan --object can --views 12\b", text)
    assert "--object milk" not in text


def test_the_twin_compiles_its_kernels_before_the_first_frame():
    """``render.warm_up`` (called by the twin's service before it is ready) leaves the shading and D435 kernels
    compiled, so a fresh checkout's first frame does not wait for numba past the camera's deadline."""
    code = ("from services.sim import render, sensor_model\n"
            "from services.sim.catalogue import load_object\n"
            "kernels = (render._compose, sensor_model._depth_edges, sensor_model._occluded)\n"
            "assert not any(k.signatures for k in kernels)\n"
            "render.warm_up(load_object('carton'))\n"
            "print([len(k.signatures) for k in kernels])\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[1, 1, 1]", proc.stdout

"""Each shared notion is defined once and imported, computed from the code of ``common/``, ``services/``, ``bench/``.

Why: two copies of a notion drift apart. Chromaticity was written twice with different numbers (one count of
8-bit offset in the turn search, a 1e-6 cut-off in the library's matching), so the same two colours agreed in one
place and not in the other; the arm's joint names were spelled in four modules; the session folder's result
files in about ten. The notions and their one home:

- the session folder's file names: ``common/session_folder.py`` (``SESSION_FILE``, ``MODEL_FILE``, ``REPORT_FILE``);
- the arm's joint names: ``services/arm/robot`` (``JOINT_NAMES``, beside the URDF that names them);
- numpy <-> Open3D clouds and chromaticity: ``services/registration/cloud.py`` (``to_o3d``, ``from_o3d``,
  ``chromaticity``, exported by the registration api).
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

from tests.common.test_import_cycles import project_modules
from tests.conftest import REPO

FILE_NAMES = {"session.json": "common/session_folder.py", "model.ply": "common/session_folder.py",
              "report.json": "common/session_folder.py"}
#: Programs that read a session folder as an outside user would, by its documented file names, and import none of
#: objscan's code on purpose (the reconstruct benchmark's independent peer).
OUTSIDE_READERS = {"bench/multiway_peer.py"}
JOINT_NAME = "robot1/joint"
JOINT_HOME = "services/arm/robot/__init__.py"
CLOUD_HOME = "services/registration/cloud.py"
CLOUD_FUNCTIONS = ("to_o3d", "from_o3d", "chromaticity")
#: An Open3D cloud's colours set from 0-255 values by hand (``to_o3d`` is the one that does it).
HAND_MADE_COLORS = re.compile(r"Vector3dVector\([^\n]*/ ?255")


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (module, class, function, attribute)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            out.add(id(node.value))
    return out


@functools.cache
def _sources(root: Path) -> list[tuple[str, Path, ast.Module]]:
    """(relative path, path, syntax tree) of every project module, parsed once per root."""
    return [(path.relative_to(root).as_posix(), path, ast.parse(path.read_text(), filename=str(path)))
            for path in project_modules(root).values()]


def spelled_file_names(root: Path) -> list[str]:
    """``file:line name`` of each code string that is exactly a session folder's file name, outside its home."""
    found = []
    for rel, _, tree in _sources(root):
        if rel in OUTSIDE_READERS:
            continue
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
                    and node.value in FILE_NAMES and FILE_NAMES[node.value] != rel):
                found.append(f"{rel}:{node.lineno} {node.value}")
    return sorted(found)


def spelled_joint_names(root: Path) -> list[str]:
    """``file:line`` of each code string (f-string parts too) that spells a joint name, outside its home."""
    found = []
    for rel, _, tree in _sources(root):
        if rel == JOINT_HOME:
            continue
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
                    and JOINT_NAME in node.value):
                found.append(f"{rel}:{node.lineno}")
    return sorted(found)


def cloud_definitions(root: Path) -> dict[str, list[str]]:
    """Module-level function name -> the files defining it, for the cloud conversions and chromaticity."""
    found: dict[str, list[str]] = {name: [] for name in CLOUD_FUNCTIONS}
    for rel, _, tree in _sources(root):
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name in found:
                found[node.name].append(rel)
    return found


def chromaticity_copies(root: Path) -> list[str]:
    """Functions named for chromaticity (``*chrom*``) other than the one, that do not call it."""
    found = []
    for rel, _, tree in _sources(root):
        for node in ast.walk(tree):
            if not isinstance(node, ast.FunctionDef) or "chrom" not in node.name.lower():
                continue
            if rel == CLOUD_HOME and node.name == "chromaticity":
                continue
            calls = {c.func.id if isinstance(c.func, ast.Name) else getattr(c.func, "attr", "")
                     for c in ast.walk(node) if isinstance(c, ast.Call)}
            if "chromaticity" not in calls:
                found.append(f"{rel}:{node.lineno} {node.name}")
    return found


def hand_made_colors(root: Path) -> list[str]:
    found = []
    for rel, path, _ in _sources(root):
        if rel == CLOUD_HOME:
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if HAND_MADE_COLORS.search(line):
                found.append(f"{rel}:{n}")
    return found


def test_session_folder_file_names_are_spelled_once():
    assert spelled_file_names(REPO) == []


def test_joint_names_are_spelled_once():
    assert spelled_joint_names(REPO) == []


def test_cloud_conversions_and_chromaticity_are_defined_once():
    assert cloud_definitions(REPO) == {name: [CLOUD_HOME] for name in CLOUD_FUNCTIONS}
    assert chromaticity_copies(REPO) == []
    assert hand_made_colors(REPO) == []


def test_the_checkers_see_copies(tmp_path):
    for pkg in ("services", "services/a", "common"):
        (tmp_path / pkg).mkdir(parents=True, exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "common" / "session_folder.py").write_text('MODEL_FILE = "model.ply"\n')
    (tmp_path / "services" / "a" / "copy.py").write_text(
        '"""Writes model.ply."""\n'
        "import open3d as o3d\n"
        'def save(p):\n    return p / "model.ply"\n'
        'NAMES = [f"robot1/joint{i}" for i in range(1, 7)]\n'
        "def to_o3d(x):\n    pcd = o3d.geometry.PointCloud()\n"
        "    pcd.colors = o3d.utility.Vector3dVector(x / 255.0)\n    return pcd\n"
        "def _chroma(rgb):\n    return rgb / rgb.sum(axis=1, keepdims=True)\n")
    assert spelled_file_names(tmp_path) == ["services/a/copy.py:4 model.ply"]
    assert spelled_joint_names(tmp_path) == ["services/a/copy.py:5"]
    assert cloud_definitions(tmp_path)["to_o3d"] == ["services/a/copy.py"]
    assert chromaticity_copies(tmp_path) == ["services/a/copy.py:10 _chroma"]
    assert hand_made_colors(tmp_path) == ["services/a/copy.py:8"]

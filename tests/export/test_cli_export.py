"""``objscan export`` as a user runs it: the files, the JSON figures in F, and a typed one-line failure."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.export.synthetic_session import make_box_session

REPO = Path(__file__).resolve().parents[2]


def objscan(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "services.cli", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return make_box_session(tmp_path_factory.mktemp("cli") / "session", cameras=6, width=120, height=90)[0]


@pytest.mark.slow  # a whole export in a fresh process: ~15 s idle, minutes on a loaded 2-core machine
def test_export_writes_the_chosen_formats_and_the_json_file(session, tmp_path):
    out, f = tmp_path / "out", tmp_path / "figures.json"
    r = objscan("export", str(session), "--out", str(out), "--format", "urdf,stl", "--mass", "0.3",
                "--no-texture", "--json", str(f))
    assert r.returncode == 0, r.stderr
    doc = json.loads(f.read_text())
    assert doc["watertight"] is True and doc["parts"] >= 1 and doc["seconds"] > 0
    assert doc["inertial"]["mass_kg"] == pytest.approx(0.3)
    assert (out / "synthetic_box.urdf").is_file() and (out / "synthetic_box.stl").is_file()
    assert not (out / "synthetic_box.glb").exists() and not (out / "synthetic_box.xml").exists()
    assert (session / "mesh.ply").is_file() and (session / "object_frame.json").is_file()


def test_export_of_a_folder_without_model_fails_on_one_line(tmp_path):
    (tmp_path / "s").mkdir()
    f = tmp_path / "err.json"
    r = objscan("export", str(tmp_path / "s"), "--out", str(tmp_path / "out"), "--json", str(f))
    assert r.returncode == 2  # bad input
    assert len(r.stderr.strip().splitlines()) == 1 and "[" in r.stderr
    assert json.loads(f.read_text())["error"]["code"] in ("no_model", "bad_session")


def test_unknown_format_is_refused(session, tmp_path):
    r = objscan("export", str(session), "--out", str(tmp_path / "o"), "--format", "fbx")
    assert r.returncode == 2 and "bad_argument" in r.stderr


@pytest.mark.slow
def test_scan_export_step_writes_into_the_session(session):
    from services.cli.cmd_scan import export_after_scan

    assert export_after_scan(session, quiet=True) == 0
    doc = json.loads((session / "export" / "export.json").read_text())
    assert doc["watertight"] and (session / "export" / "synthetic_box.xml").is_file()

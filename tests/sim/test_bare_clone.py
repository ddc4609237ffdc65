"""A copy of the repository alone, with nothing beside it, scans its demo object to a model.

``git archive HEAD`` is what a clone holds (committed files only). It is unpacked into an empty folder, so no
data folder beside a developer's checkout is reachable, and ``objscan scan --object carton`` runs there with
no ``OBJSCAN_*`` variable set: the whole cell (twin, arm, camera, grasp, registration, orchestrator) starts
from the copy and ends with a model measured against the carton's own mesh. Real processes over Zenoh on
loopback, MuJoCo physics, 3 views: minutes (16 on a loaded 2-core machine), so ``slow``.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from tests.report.test_real_acquisition import free_port

REPO = Path(__file__).resolve().parents[2]


def bare_copy(folder: Path) -> Path:
    """The repository's committed files (``git archive HEAD``) unpacked as ``folder/objscan``, alone in
    ``folder``."""
    archive = subprocess.run(["git", "archive", "--format=tar", "HEAD"], cwd=REPO, capture_output=True, check=True,
                             timeout=120).stdout
    copy = folder / "objscan"
    copy.mkdir(parents=True)
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(copy, filter="data")
    return copy


def bare_env(copy: Path) -> dict[str, str]:
    """The caller's environment without any objscan setting, importing the copy's code."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("OBJSCAN_")}
    env.update(OMP_NUM_THREADS="1", PYTHONPATH=str(copy), HOME=str(copy.parent / "home"),
               XDG_CACHE_HOME=str(copy.parent / "cache"))
    return env


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_a_bare_copy_of_the_repository_scans_the_demo_carton(tmp_path):
    if not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    empty = tmp_path / "empty"
    empty.mkdir()
    copy = bare_copy(empty)
    assert [p.name for p in empty.iterdir()] == ["objscan"]  # nothing beside the copy: no shared data folder
    assert not (copy.parent / "shared").exists() and not (copy / ".." / "shared" / "data" / "hope").exists()
    assert (copy / "services" / "sim" / "objects" / "carton" / "textured.obj").is_file()
    assert (copy / "services" / "sim" / "demo_meshes.py").is_file()
    env = bare_env(copy)
    (copy.parent / "home").mkdir()

    where = subprocess.run([sys.executable, "-c", "import services, services.sim.catalogue as c; "
                            "print(services.__file__); print(c.hope_names())"], cwd=copy, env=env,
                           capture_output=True, text=True, check=True, timeout=120).stdout.split("\n")
    assert Path(where[0]).resolve().is_relative_to(copy.resolve()), where  # the copy's code, not the checkout's
    assert where[1] == "[]"  # and no HOPE data reachable

    out = copy / "sessions" / "carton"
    proc = subprocess.run([sys.executable, "-m", "services.cli.main", "scan", "--object", "carton", "--views", "3",
                           "--out", str(out), "--port", str(free_port()), "--no-record", "--json"],
                          cwd=copy, env=env, capture_output=True, text=True, timeout=1700)
    assert (out / "journal.json").is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    journal = json.loads((out / "journal.json").read_text())
    assert proc.returncode == 0 and journal["status"] == "done", (journal.get("error"), proc.stderr[-3000:])
    model = Path(journal["model_path"])
    model = model if model.is_absolute() else copy / model
    assert model.is_file() and model.resolve().is_relative_to(copy.resolve()), journal["model_path"]
    # 3 views 30 degrees apart see a third of the carton: what the model holds lies on it (accuracy, model to
    # mesh); completeness and Chamfer need the 12 views of scripts/demo.sh
    assert journal["accuracy"]["accuracy_mm"] < 2.0, journal["accuracy"]

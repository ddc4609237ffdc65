"""A real short acquisition (every service as its own process over Zenoh), then its report and library entry.

Slow (several minutes on a loaded 2-core machine): marked ``slow``. The run is ``objscan scan --object milk
--views 3 --profile ideal``. It must finish; its report must be a valid page that tells the run's
status; the model goes into the library and ``find`` recognises it from the session's own first view.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from common.session_folder import read_session
from services.library import ModelLibrary, add_session_model
from services.report import build_report
from tests.conftest import shared_data
from tests.report.test_report import parse

REPO = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_report_and_library_entry_of_a_real_acquisition(tmp_path):
    shared_data("hope", "milk")
    out = tmp_path / "session"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, "-m", "services.cli.main", "scan", "--object", "milk", "--views", "3",
                           "--profile", "ideal", "--out", str(out), "--port", str(free_port())],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=1400)
    assert (out / "journal.json").is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    journal = json.loads((out / "journal.json").read_text())
    page_path = build_report(out)
    page = page_path.read_text()
    p = parse(page)
    assert p.errors == [] and p.stack == []
    assert f"<td>{journal['status']}</td>" in page
    info = read_session(out)
    complete_scans = sum(len(info.scans(int(v["index"]))) for v in info.views)
    assert sum(i["alt"].startswith("scan_") for i in p.images) == complete_scans
    if CHROMIUM:
        shot = tmp_path / "report.png"
        subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                        "--disable-component-update", "--no-first-run", f"--user-data-dir={tmp_path / 'chrome'}",
                        f"--screenshot={shot}", "--window-size=1200,3000", page_path.as_uri()],
                       capture_output=True, timeout=180, check=True)
        assert shot.stat().st_size > 50_000
    assert journal["status"] == "done", (journal.get("error"), proc.stdout[-2000:])
    assert "No model.ply" not in page and "registration graph" in page
    entry_id = add_session_model(tmp_path / "models", out)
    lib = ModelLibrary(tmp_path / "models")
    assert lib.get(entry_id).metadata.object_name == "milk"
    from services.registration.cloud import read_ply

    view0 = read_ply(out / "view_00" / "object.ply")
    best = lib.find(view0.xyz, top_k=1, rgb=view0.rgb)[0]
    # view 0's partial cloud against a 3-view model: ~0.8 of its points lie on it, whichever grasps turned it
    assert best.id == entry_id and best.detail["fitness"] > 0.7, best.detail

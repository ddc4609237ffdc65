"""The report in a real browser: headless Chromium loads it, decodes every image, and screenshots it.

Needs Debian's ``chromium`` (``apt-get install -y chromium``); skipped with that reason when absent.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile

import numpy as np
import pytest
from PIL import Image

from services.report import build_report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--no-first-run", "--hide-scrollbars"]


def chromium(*args: str) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args], capture_output=True,
                              text=True, timeout=180)


@pytest.fixture(scope="module")
def report(milk_session, tmp_path_factory):
    return build_report(milk_session, tmp_path_factory.mktemp("br") / "report.html")


def test_every_image_decodes_in_the_browser(report, tmp_path):
    probe = tmp_path / "probe.html"
    script = ("<script>window.addEventListener('load',()=>{const im=[...document.images];"
              "document.body.setAttribute('data-images',im.filter(i=>i.complete&&i.naturalWidth>0).length"
              "+'/'+im.length)})</script></body>")
    probe.write_text(report.read_text().replace("</body>", script))
    proc = chromium("--dump-dom", probe.as_uri())
    assert proc.returncode == 0, proc.stderr[-2000:]
    n = report.read_text().count("<img ")
    assert n > 20
    assert f'data-images="{n}/{n}"' in proc.stdout


def test_screenshot_shows_a_rendered_page(report, tmp_path):
    shot = tmp_path / "report.png"
    proc = chromium(f"--screenshot={shot}", "--window-size=1200,3000", report.as_uri())
    assert proc.returncode == 0 and shot.is_file(), proc.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB"))
    assert img.shape == (3000, 1200, 3)
    background = np.array([250, 250, 250])
    ink = (np.abs(img.astype(int) - background).sum(axis=2) > 30).mean()
    assert ink > 0.08  # text, tables, renders: far from a blank page (this one measured 0.135)
    saturated = (img.max(axis=2).astype(int) - img.min(axis=2) > 40).mean()
    assert saturated > 0.03  # photos and renders, not just grey text on a flat background
    # the model renders (above the fold) show the milk carton's red print (measured ~7000 px)
    top = img[:1500].reshape(-1, 3).astype(int)
    red = ((top[:, 0] > 120) & (top[:, 0] > 2 * top[:, 1]) & (top[:, 0] > 2 * top[:, 2])).sum()
    assert red > 3000

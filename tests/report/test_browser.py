"""The report in a real browser: headless Chromium loads it, decodes every image, and screenshots it.

Needs Debian's ``chromium`` (``apt-get install -y chromium``); skipped with that reason when absent.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

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


def probe_result(page: str, probe_script: str, attribute: str, folder: Path) -> dict:
    """Run ``page`` with ``probe_script`` before ``</body>`` in headless Chromium and return the JSON the probe
    left in the body's ``attribute`` (the probe drives the page's own viewer, so this reads what it drew)."""
    probe = folder / "probe.html"
    probe.write_text(page.replace("</body>", probe_script))
    proc = chromium("--dump-dom", "--virtual-time-budget=10000", probe.as_uri())
    assert proc.returncode == 0, proc.stderr[-2000:]
    m = re.search(rf'{attribute}="([^"]*)"', proc.stdout)
    assert m, "the probe did not run (script error?)"
    return json.loads(html.unescape(m.group(1)))


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
    # the model renders show the milk carton's red print (measured ~7000 px; below the interactive viewer,
    # whose default colouring is the error map)
    top = img.reshape(-1, 3).astype(int)
    red = ((top[:, 0] > 120) & (top[:, 0] > 2 * top[:, 1]) & (top[:, 0] > 2 * top[:, 2])).sum()
    assert red > 3000


# the interactive model (services/report/viewer.py): a probe drags, zooms and recolours it in the browser and
# compares the canvas before and after each step
VIEWER_PROBE = """<script>window.addEventListener('load',()=>{
const el=document.getElementById('model3d'),cv=el.querySelector('canvas'),snap=()=>cv.toDataURL();
const ink=()=>{const d=cv.getContext('2d').getImageData(0,0,cv.width,cv.height).data;let k=0;
  for(let i=0;i<d.length;i+=4)if(d[i]+d[i+1]+d[i+2]<700)k++;return k;};
const r=cv.getBoundingClientRect(),ev=(t,x,y)=>cv.dispatchEvent(new PointerEvent(t,{clientX:r.left+x,
  clientY:r.top+y,pointerId:1,bubbles:true}));
const a=snap(),inkA=ink();ev('pointerdown',300,200);ev('pointermove',390,230);ev('pointerup',390,230);
const b=snap(),inkB=ink();
cv.dispatchEvent(new WheelEvent('wheel',{deltaY:-300,bubbles:true,cancelable:true}));const c=snap(),inkC=ink();
el.querySelector("button[data-mode='color']").click();const d=snap();
el.querySelector('button:not([data-mode]):not([data-zoom])').click();const e=snap();
document.body.setAttribute('data-viewer',JSON.stringify({turned:a!==b,zoomed:b!==c,recoloured:c!==d,
  reset_restores:e===a,ink:inkA,ink_turned:inkB,ink_zoomed:inkC,points:q0()}));
function q0(){return atob(el.dataset.xyz).length/6;}});</script></body>"""


def test_the_model_turns_zooms_and_recolours_in_the_browser(report, tmp_path):
    page = report.read_text()
    assert "<canvas" in page and "http://" not in page.split("<body>", 1)[1].replace("http://www.w3.org", "")
    assert "https://" not in page  # offline: no CDN, no remote script or font
    res = probe_result(page, VIEWER_PROBE, "data-viewer", tmp_path)
    assert res["turned"] and res["zoomed"] and res["recoloured"], res
    assert res["reset_restores"], res  # reset: the first view again (angle, zoom, error colouring)
    assert res["points"] > 5000 and res["ink"] > 5000, res  # the model covers the canvas, not a few dots
    assert res["ink_zoomed"] > res["ink_turned"], res  # zooming in makes it bigger (same turn before and after)


VIEWER_ONLY = ("<style>body>*:not(section.model3d){display:none}</style><script>document.querySelectorAll('section')"
               ".forEach(s=>{if(s.querySelector('#model3d'))s.className='model3d';});</script></body>")


def test_screenshot_of_the_interactive_model(report, tmp_path):
    """What docs/images/report_model3d.png shows (OBJSCAN_DOCS_IMAGES=1 writes it): the Model section alone."""
    page = tmp_path / "viewer.html"
    page.write_text(report.read_text().replace("</body>", VIEWER_ONLY))
    shot = tmp_path / "model3d.png"
    proc = chromium(f"--screenshot={shot}", "--window-size=780,640", "--virtual-time-budget=10000", page.as_uri())
    assert proc.returncode == 0 and shot.is_file(), proc.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    # the error colouring is viridis: purple-blue-green-yellow, no red; count the canvas' coloured pixels
    sat = img.max(axis=2) - img.min(axis=2) > 40
    assert sat.sum() > 8000, sat.sum()
    greenish = sat & (img[..., 1] > img[..., 0])  # viridis is greener than red over most of its range
    assert greenish.sum() > 0.5 * sat.sum()
    if os.environ.get("OBJSCAN_DOCS_IMAGES") == "1":
        shutil.copy(shot, Path(__file__).resolve().parents[2] / "docs" / "images" / "report_model3d.png")

"""The report shows the exported closed mesh (``SESSION/mesh.ply``) in the inline viewer beside the point
model: the page carries the mesh's vertices, triangles and colours, and a browser draws, turns and zooms it."""

from __future__ import annotations

import base64
import json
import re
import shutil

import numpy as np
import open3d as o3d
import pytest

from services.report import build_report
from services.report.viewer import mesh_viewer_html
from tests.report.test_browser import CHROMIUM, probe_result


def _attr(page: str, element_id: str, name: str) -> str:
    block = re.search(rf'<div id="{element_id}"[^>]*>', page).group(0)
    return re.search(rf'data-{name}="([^"]*)"', block).group(1)


def test_the_mesh_travels_in_the_page():
    box = o3d.geometry.TriangleMesh.create_box(0.06, 0.04, 0.1)
    v, t = np.asarray(box.vertices), np.asarray(box.triangles)
    rgb = np.random.default_rng(0).integers(0, 255, (len(t), 3), dtype=np.uint8)
    page = mesh_viewer_html(v, t, rgb)
    tri = np.frombuffer(base64.b64decode(_attr(page, "mesh3d", "tri")), dtype="<u4").reshape(-1, 3)
    assert np.array_equal(tri, t)
    assert np.array_equal(np.frombuffer(base64.b64decode(_attr(page, "mesh3d", "rgb")), np.uint8).reshape(-1, 3), rgb)
    q = np.frombuffer(base64.b64decode(_attr(page, "mesh3d", "xyz")), dtype="<u2").reshape(-1, 3)
    lo, hi = np.array(json.loads(_attr(page, "mesh3d", "lo"))), np.array(json.loads(_attr(page, "mesh3d", "hi")))
    assert np.abs(lo + (hi - lo) * q / 65535.0 - v).max() < 1e-5


@pytest.fixture(scope="module")
def meshed_session(milk_session, tmp_path_factory):
    """The milk session with an exported-like closed mesh beside its model (a copy: the others stay as they are)."""
    session = tmp_path_factory.mktemp("meshed") / "milk"
    shutil.copytree(milk_session, session)
    pts = np.asarray(o3d.io.read_point_cloud(str(session / "model.ply")).points)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    box = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
    box.translate(lo)
    box = box.subdivide_midpoint(3)
    box.vertex_colors = o3d.utility.Vector3dVector(np.tile([0.85, 0.1, 0.1], (len(box.vertices), 1)))
    o3d.io.write_triangle_mesh(str(session / "mesh.ply"), box)
    return session, len(box.triangles), build_report(session, session / "report.html").read_text()


def test_the_report_shows_the_mesh_beside_the_point_model(meshed_session):
    _, n_triangles, page = meshed_session
    assert 'id="model3d"' in page and 'id="mesh3d"' in page
    assert page.index('id="model3d"') < page.index('id="mesh3d"')
    assert len(base64.b64decode(_attr(page, "mesh3d", "tri"))) == n_triangles * 12


MESH_PROBE = """<script>window.addEventListener('load',()=>{
const el=document.getElementById('mesh3d'),cv=el.querySelector('canvas'),snap=()=>cv.toDataURL();
const red=()=>{const d=cv.getContext('2d').getImageData(0,0,cv.width,cv.height).data;let k=0;
  for(let i=0;i<d.length;i+=4)if(d[i]>80&&d[i]>2*d[i+1]&&d[i]>2*d[i+2])k++;return k;};
const r=cv.getBoundingClientRect(),ev=(t,x,y)=>cv.dispatchEvent(new PointerEvent(t,{clientX:r.left+x,
  clientY:r.top+y,pointerId:1,bubbles:true}));
const a=snap(),redA=red();ev('pointerdown',300,200);ev('pointermove',390,230);ev('pointerup',390,230);const b=snap();
cv.dispatchEvent(new WheelEvent('wheel',{deltaY:-300,bubbles:true,cancelable:true}));const redC=red();
document.body.setAttribute('data-mesh',JSON.stringify({turned:a!==b,red:redA,red_zoomed:redC,
  drawn:+el.dataset.drawn}));});</script></body>"""


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")
def test_the_mesh_is_drawn_and_turns_in_the_browser(meshed_session, tmp_path):
    page = meshed_session[2]
    res = probe_result(page, MESH_PROBE, "data-mesh", tmp_path)
    assert res["turned"] and res["drawn"] >= 3, res
    assert res["red"] > 20000, res  # a solid red box fills a good part of the 720 x 480 canvas
    assert res["red_zoomed"] > res["red"], res

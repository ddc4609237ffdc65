"""The HTML report of a finished session: a valid, self-contained page showing what the session holds.

The session is a fake-but-valid acquisition folder (tests/library/fake_session.py: the twin's scans,
static registration, grasp planning, dynamic registration, evaluation), so every figure the page prints
can be checked against the files it came from.
"""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
from html.parser import HTMLParser

import numpy as np
import pytest
from PIL import Image

from services.report import ReportError, build_report

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


class PageParser(HTMLParser):
    """Collects tags, checks nesting of non-void elements, and gathers images, SVG shapes and text."""

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.images: list[dict[str, str]] = []
        self.tags: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):  # noqa: ANN001
        self.tags.append(tag)
        if tag == "img":
            self.images.append(dict(attrs))
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):  # noqa: ANN001
        self.tags.append(tag)
        if tag == "img":
            self.images.append(dict(attrs))

    def handle_endtag(self, tag):  # noqa: ANN001
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes {self.stack[-1] if self.stack else 'nothing'}")
        else:
            self.stack.pop()

    def handle_data(self, data):  # noqa: ANN001
        self.text.append(data)


def parse(page: str) -> PageParser:
    p = PageParser()
    p.feed(page)
    p.close()
    return p


@pytest.fixture(scope="module")
def session(milk_session):
    return milk_session


@pytest.fixture(scope="module")
def page(session):
    path = build_report(session)
    assert path == session / "report.html"
    return path.read_text()


def test_page_is_well_formed_and_self_contained(page):
    assert page.startswith("<!DOCTYPE html>")
    p = parse(page)
    assert p.errors == [] and p.stack == []
    assert p.tags.count("html") == 1 and "title" in p.tags
    # nothing is fetched: every image is inline PNG, one inline script (the model viewer) and no external
    # links, scripts or stylesheets
    assert not re.search(r"(src|href)=\"(?!data:)", page)
    assert re.findall(r"<script[^>]*>", page) == ["<script>"]
    assert "http://" not in page.replace('xmlns="http://www.w3.org/2000/svg"', "") and "https://" not in page
    for img in p.images:
        assert img["src"].startswith("data:image/png;base64,")
        im = Image.open(io.BytesIO(base64.b64decode(img["src"].split(",", 1)[1])))
        im.verify()
        assert img.get("alt")


def test_views_show_scans_object_and_the_chosen_grasp(session, page):
    p = parse(page)
    captions = [i["alt"] for i in p.images]
    assert sum(c.startswith("scan_") for c in captions) == 4 * 3
    object_imgs = [c for c in captions if c.startswith("object")]
    assert len(object_imgs) == 4
    # views 0-2 turned the object with a planned grasp, the last one did not
    assert sum("chosen grasp" in c for c in object_imgs) == 3
    assert page.count("<tr class='chosen'>") == 3
    journal = json.loads((session / "journal.json").read_text())
    turned = [d for d in journal["decisions"] if d["what"] == "turned"]
    assert len(turned) == 3 and page.count("turned with") == 3


def test_object_render_draws_the_grasp_contacts(session, page):
    p = parse(page)
    img = next(i for i in p.images if "chosen grasp" in i["alt"])
    arr = np.asarray(Image.open(io.BytesIO(base64.b64decode(img["src"].split(",", 1)[1]))).convert("RGB"))
    crimson = (np.abs(arr.astype(int) - [220, 20, 60]).sum(axis=2) < 60).sum()
    assert crimson > 30  # the contact marks and the closing line


def test_registration_graph_has_every_edge_with_its_fitness(session, page):
    figures = json.loads((session / "report.json").read_text())["model_figures"]
    svg = re.search(r"<svg[^>]*aria-label=\"registration graph\".*?</svg>", page, re.S).group(0)
    assert svg.count("<line") == len(figures["edges"]) == 4
    assert svg.count("<circle") == 4
    for e in figures["edges"]:
        assert f">{e['fitness']:.2f}<" in svg
        assert f"view {e['source_view']} -&gt; view {e['target_view']}" in svg


def test_accuracy_section_matches_the_session_figures(session, page):
    acc = json.loads((session / "report.json").read_text())["accuracy"]
    assert f"{acc['chamfer_mm']:.2f} mm" in page
    assert f"{100 * acc['fscore_2mm']:.1f} %" in page
    m = re.search(r"median / 95th pct / max</th><td>([\d.]+) / ([\d.]+) / ([\d.]+) mm", page)
    median, p95, worst = map(float, m.groups())
    assert 0.0 < median <= p95 <= worst < 10.0
    # the error map is drawn in the colormap's colours (viridis), and the model renders in its own
    p = parse(page)
    assert sum(i["alt"].startswith("azimuth") for i in p.images) == 3 + 5


def test_timings_are_listed(session, page):
    timings = json.loads((session / "journal.json").read_text())["timings_s"]
    svg = re.search(r"<svg[^>]*aria-label=\"timings\".*?</svg>", page, re.S).group(0)
    for name, seconds in timings.items():
        assert f">{name}<" in svg and f"{seconds:.2f} s" in svg


def test_failed_session_still_gets_a_page_that_says_what_is_missing(session, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(session, broken)
    (broken / "model.ply").unlink()
    (broken / "report.json").unlink()
    shutil.rmtree(broken / "view_03")
    out = build_report(broken, tmp_path / "out" / "r.html")
    page = out.read_text()
    assert parse(page).errors == []
    assert "No model.ply in the session" in page and "No dynamic registration figures" in page
    # view 3 is listed by session.json but its folder is gone: its card says so, the others are intact
    assert "<h3>View 3</h3>" in page and page.count("No isolated object (view not registered)") == 1
    assert sum(i["alt"].startswith("scan_") for i in parse(page).images) == 3 * 3


def test_not_a_session_is_a_typed_error(tmp_path):
    with pytest.raises(ReportError) as exc:
        build_report(tmp_path / "nothing")
    assert exc.value.code == "bad_session"


def test_an_unaccepted_model_is_flagged_in_the_summary(session, tmp_path):
    flagged = tmp_path / "flagged"
    shutil.copytree(session, flagged)
    report = json.loads((flagged / "report.json").read_text())
    report.update({"accepted": False, "why": "loop closure 89.80 deg > 5 deg"})
    report["model_figures"]["views_left_out"] = [5]
    (flagged / "report.json").write_text(json.dumps(report))
    page = build_report(flagged, tmp_path / "out" / "r.html").read_text()
    assert "NO: loop closure 89.80 deg &gt; 5 deg" in page
    assert re.search(r"<th>views left out</th><td>5</td>", page)

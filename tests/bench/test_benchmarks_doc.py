"""BENCHMARKS.md and ``bench/latest/`` describe each other: every figure's JSON is there, and nothing else.

A section names the JSON its figures come from (``bench/latest/NAME.json``; ``NAME`` stands for one file per
object). A named file that is missing leaves a figure without its source; a file no section names is a result
nobody reads, and it goes stale.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LATEST = ROOT / "bench" / "latest"
REFERENCE = re.compile(r"bench/latest/([A-Za-z0-9_]+\.json)")


def referenced() -> list[str]:
    return sorted(set(REFERENCE.findall((ROOT / "BENCHMARKS.md").read_text(encoding="utf-8"))))


def files_for(name: str) -> list[Path]:
    """The files a reference names: ``NAME`` matches one object's name."""
    return sorted(LATEST.glob(name.replace("NAME", "*"))) if "NAME" in name else [LATEST / name]


def test_every_json_the_benchmarks_name_exists_and_parses() -> None:
    names = referenced()
    assert names, "BENCHMARKS.md names no JSON in bench/latest"
    for name in names:
        paths = [p for p in files_for(name) if p.is_file()]
        assert paths, f"BENCHMARKS.md names bench/latest/{name}, which is not there"
        for path in paths:
            json.loads(path.read_text(encoding="utf-8"))


def test_every_file_in_bench_latest_is_named_by_a_section() -> None:
    named = {p.name for name in referenced() for p in files_for(name)}
    unnamed = sorted(p.name for p in LATEST.iterdir() if p.is_file() and p.name not in named)
    assert not unnamed, f"in bench/latest but named by no section of BENCHMARKS.md: {unnamed}"


def test_the_results_page_stays_a_page_of_current_figures() -> None:
    """BENCHMARKS.md holds the current figure of each benchmark, not their history: under 400 lines, and every
    section names the command that produced it."""
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 400
    sections = text.split("\n## ")[1:]
    assert sections and all("objscan " in s or "python -m bench" in s for s in sections)


def test_the_results_name_no_folder_of_the_machine_that_measured_them() -> None:
    """A figure's JSON says which session or file it came from by name, not by where it lay on one machine."""
    machine_path = re.compile(r'"/(?:tmp|work|home|root)/')
    offenders = [p.name for p in sorted(LATEST.glob("*.json")) if machine_path.search(p.read_text(encoding="utf-8"))]
    assert offenders == []

"""The product speaks of the product: no trace of how it was developed in what a user reads.

README.md, BENCHMARKS.md, docs/, the code (services/, common/, bench/) and the tests describe what objscan does
and why. A pointer to a work item ("issue N", "#NN"), a numbered round or wave of work, or a development
session ("session N"; a scan session is a product word, but a product text never numbers one that way) says
nothing to a user and goes stale, so the scan below fails on any of them. The documentation also must not
point into one developer's machine (``/work/...``, ``/home/...``, a worktree folder).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TREES = ("README.md", "BENCHMARKS.md", "docs", "services", "common", "bench", "tests")
DOC_TREES = ("README.md", "BENCHMARKS.md", "docs", "SECURITY.md")

#: The words of the development process (matched case-insensitively, anywhere in a line).
DEVELOPMENT_WORDS = re.compile(r"session [0-9]|issue [0-9]|#[0-9]{2}\b|round [0-9]|wave [0-9]", re.IGNORECASE)
#: Paths of a developer's machine, refused in the documentation.
DEVELOPER_PATHS = re.compile(r"/work/|/home/|\bwt-[a-z]+/")

#: Genuine product uses a pattern would otherwise flag: (path relative to the repository, text on the line).
ALLOWED: tuple[tuple[str, str], ...] = ()


def text_files(*trees: str) -> list[Path]:
    """Every text file under ``trees`` (binary files, e.g. images and meshes, have a NUL byte or are not UTF-8)."""
    files: list[Path] = []
    for tree in trees:
        top = ROOT / tree
        candidates = [top] if top.is_file() else sorted(p for p in top.rglob("*") if p.is_file())
        for path in candidates:
            if "__pycache__" in path.parts:
                continue
            data = path.read_bytes()
            if b"\0" in data[:8192]:
                continue
            try:
                data.decode("utf-8")
            except UnicodeDecodeError:
                continue
            files.append(path)
    return files


def matches(pattern: re.Pattern[str], text: str) -> list[tuple[int, str]]:
    """(line number, line) of each line of ``text`` where ``pattern`` occurs."""
    return [(n, line) for n, line in enumerate(text.splitlines(), 1) if pattern.search(line)]


def offending(pattern: re.Pattern[str], files: list[Path]) -> list[str]:
    found = []
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        for n, line in matches(pattern, path.read_text(encoding="utf-8")):
            if any(rel == allowed_path and text in line for allowed_path, text in ALLOWED):
                continue
            found.append(f"{rel}:{n}: {line.strip()[:160]}")
    return found


def test_no_development_words_in_the_product() -> None:
    found = offending(DEVELOPMENT_WORDS, text_files(*TREES))
    assert not found, "words of the development process in the product:\n" + "\n".join(found)


def test_the_documentation_points_into_no_developer_machine() -> None:
    found = offending(DEVELOPER_PATHS, text_files(*DOC_TREES))
    assert not found, "developer paths in the documentation:\n" + "\n".join(found)


@pytest.mark.parametrize(("words", "number"), [("fixed in issue ", 17), ("see #", 42), ("Round ", 3),
                                               ("measured in session ", 6), ("wave ", 2)])
def test_the_scan_catches_development_words(words: str, number: int) -> None:
    line = f"{words}{number} of the work"  # joined here, so this file itself passes the scan
    assert matches(DEVELOPMENT_WORDS, line)


@pytest.mark.parametrize("line", ["a scan session writes model.ply", "the session folder holds 12 views",
                                  "colour #ff0000 is red", "12 views of 30°"])
def test_product_sentences_pass_the_scan(line: str) -> None:
    assert not matches(DEVELOPMENT_WORDS, line)

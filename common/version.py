"""objscan's version, in one place: what ``objscan --version`` prints and recordings store.

Read from the installed distribution's metadata; a plain checkout that was never ``pip install``-ed
(PYTHONPATH=.) falls back to ``pyproject.toml`` beside the package, so the answer is never a guess.
"""

from __future__ import annotations

import re
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def objscan_version() -> str:
    """The version string, e.g. ``0.1.0``; ``unknown`` only when neither source exists."""
    try:
        text = PYPROJECT.read_text()
    except OSError:
        text = ""
    # the checkout's own pyproject wins: an editable install elsewhere may be an older copy
    m = re.search(r'(?m)^version\s*=\s*"([^"]+)"', text)
    if m:
        return m.group(1)
    try:
        from importlib.metadata import PackageNotFoundError, version

        return version("objscan")
    except PackageNotFoundError:
        return "unknown"

"""The CLI's one console for progress and result lines (``console.quiet`` under ``--json``).

Its own module so that commands which only print (``reconstruct``, ``export``, ``import``) do not import
``cmd_scan`` and, through it, Zenoh, the cell launcher and the acquisition config they never use.
"""

from __future__ import annotations

from rich.console import Console

console = Console()

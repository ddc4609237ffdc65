"""Printing benchmark figures as a table (nested dicts become dotted rows)."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table


def flatten(figures: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """Dotted rows of nested figures; a list of dicts (one per object) is labelled by each one's
    ``set``/``object`` (or its position)."""
    rows: list[tuple[str, Any]] = []
    for key, value in figures.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            rows.extend(flatten(value, name + "."))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for i, item in enumerate(value):
                label = ":".join(str(item[k]) for k in ("set", "object") if k in item) or str(i)
                rows.extend(flatten({k: v for k, v in item.items() if k not in ("set", "object")},
                                    f"{name}.{label}."))
        else:
            rows.append((name, value))
    return rows


def print_figures(title: str, figures: dict[str, Any]) -> None:
    table = Table(title=f"objscan bench {title}")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for name, value in flatten(figures):
        table.add_row(name, f"{value:.4g}" if isinstance(value, float) else str(value))
    Console().print(table)

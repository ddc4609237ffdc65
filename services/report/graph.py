"""The registration graph as inline SVG: views on a circle, one edge per registered pair, colored and
labelled by its fitness; the edge the paper's chain dropped is dashed."""

from __future__ import annotations

import html
from typing import Any

import numpy as np


def fitness_color(f: float | None) -> str:
    """Red (0) -> amber (0.5) -> green (1) for a fitness in [0, 1]; grey when unknown."""
    if f is None or not np.isfinite(f):
        return "#999999"
    f = float(np.clip(f, 0.0, 1.0))
    r = int(220 if f < 0.5 else 220 - (f - 0.5) * 2 * 180)
    g = int(60 + f * 2 * 120 if f < 0.5 else 180)
    return f"#{r:02x}{g:02x}40"


def registration_graph_svg(n_views: int, edges: list[dict[str, Any]], dropped_edge: int | None = None,
                           size: int = 460) -> str:
    """SVG of the view graph; ``edges`` are ``model_figures.edges`` dicts (source_view, target_view, fitness)."""
    if n_views <= 0:
        return "<p>No views.</p>"
    c = size / 2.0
    R = size / 2.0 - 48
    angles = np.pi / 2 - 2 * np.pi * np.arange(n_views) / n_views
    pos = np.column_stack([c + R * np.cos(angles), c - R * np.sin(angles)])
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" '
             f'viewBox="0 0 {size} {size}" role="img" aria-label="registration graph">']
    for e in edges:
        s, t = int(e.get("source_view", -1)), int(e.get("target_view", -1))
        if not (0 <= s < n_views and 0 <= t < n_views):
            continue
        fit = e.get("fitness")
        fit = float(fit) if isinstance(fit, int | float) else None
        dashed = ' stroke-dasharray="7 5"' if dropped_edge is not None and int(e.get("index", -1)) == dropped_edge \
            else ""
        (x1, y1), (x2, y2) = pos[s], pos[t]
        width = 2 + 6 * (fit or 0.0)
        title = html.escape(f"view {s} -> view {t}: fitness {fit if fit is None else round(fit, 3)}, "
                            f"rmse {e.get('rmse_mm', '?')} mm, path {e.get('path', '?')}")
        parts.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{fitness_color(fit)}" '
                     f'stroke-width="{width:.1f}" stroke-linecap="round"{dashed}><title>{title}</title></line>')
        mx, my = (x1 + x2) / 2, (y1 + y2) / 2
        # push the label off the edge toward the outside of the circle
        out = np.array([mx - c, my - c])
        out = out / (np.linalg.norm(out) or 1.0) * 16
        label = "?" if fit is None else f"{fit:.2f}"
        parts.append(f'<text x="{mx + out[0]:.1f}" y="{my + out[1] + 4:.1f}" font-size="12" text-anchor="middle" '
                     f'fill="#333">{label}</text>')
    for k, (x, y) in enumerate(pos):
        parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="15" fill="#1f4e79"/>'
                     f'<text x="{x:.1f}" y="{y + 4:.1f}" font-size="12" text-anchor="middle" fill="#fff">{k}</text>')
    parts.append("</svg>")
    return "".join(parts)


def timings_svg(timings: dict[str, float], width: int = 560) -> str:
    """Horizontal bars of seconds per step."""
    items = [(k, float(v)) for k, v in timings.items() if isinstance(v, int | float)]
    if not items:
        return "<p>No timings recorded.</p>"
    top = max(v for _, v in items) or 1.0
    row = 24
    height = row * len(items) + 8
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
             f'aria-label="timings">']
    for i, (name, v) in enumerate(items):
        y = 4 + i * row
        w = (width - 230) * v / top
        parts.append(f'<text x="0" y="{y + 15}" font-size="13">{html.escape(name)}</text>'
                     f'<rect x="120" y="{y + 3}" width="{max(w, 1):.1f}" height="16" fill="#4a90c2"/>'
                     f'<text x="{126 + w:.1f}" y="{y + 15}" font-size="12">{v:.2f} s</text>')
    parts.append("</svg>")
    return "".join(parts)

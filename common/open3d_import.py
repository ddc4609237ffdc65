"""Open3D without the start-up of its browser visualiser: ``draw_plotly`` is loaded when first called.

Why: ``import open3d`` imports ``open3d.visualization.draw_plotly``, which imports Plotly and Dash (and through
Dash IPython, Flask, Werkzeug, requests): about as much CPU as the rest of Open3D's import, in every process that
touches Open3D (each reconstruct, each registration worker, each service), for a viewer objscan never opens.
``defer_plotly_drawing()`` puts a small stand-in for that one module in ``sys.modules`` before Open3D is
imported; its three functions (``get_plotly_fig``, ``draw_plotly``, ``draw_plotly_server``) load the real module
on first call and hand over to it, so a caller who does draw with Plotly gets exactly Open3D's own function.
Nothing else of Open3D changes. Called from the ``common``, ``services`` and ``bench`` packages' ``__init__``,
which every objscan process imports before it imports Open3D.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

MODULE = "open3d.visualization.draw_plotly"
FUNCTIONS = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


def _real_module(path: Path) -> types.ModuleType:
    """Open3D's own ``draw_plotly`` module, loaded now under its own name (replacing the stand-in)."""
    current = sys.modules.get(MODULE)
    if current is not None and not getattr(current, "__objscan_deferred__", False):
        return current
    spec = importlib.util.spec_from_file_location(MODULE, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {MODULE} from {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[MODULE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(MODULE, None)
        raise
    return module


def _forward(path: Path, name: str) -> Callable[..., Any]:
    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(_real_module(path), name)(*args, **kwargs)

    call.__name__ = name
    call.__doc__ = f"Open3D's ``{name}``, loaded (with Plotly and Dash) on this first call."
    return call


def defer_plotly_drawing() -> bool:
    """Install the stand-in when Open3D is installed and not imported yet; True when it is in place."""
    if MODULE in sys.modules:
        return bool(getattr(sys.modules[MODULE], "__objscan_deferred__", False))
    if "open3d" in sys.modules:
        return False  # too late: Open3D's import has run already
    try:
        spec = importlib.util.find_spec("open3d")
    except (ImportError, ValueError):
        return False
    if spec is None or not spec.submodule_search_locations:
        return False
    path = Path(next(iter(spec.submodule_search_locations))) / "visualization" / "draw_plotly.py"
    if not path.is_file():
        return False
    stub = types.ModuleType(MODULE, "Open3D's draw_plotly, loaded on first use (common/open3d_import.py)")
    stub.__file__ = str(path)
    stub.__objscan_deferred__ = True  # type: ignore[attr-defined]
    for name in FUNCTIONS:
        setattr(stub, name, _forward(path, name))
    sys.modules[MODULE] = stub
    return True

"""Convex collision parts of an object's mesh for the physics mode, cached per mesh.

MuJoCo collides meshes through their convex hulls, so a concave object (a mug, a bowl) needs a convex
decomposition. ``coacd`` (approximate convex decomposition) is used when installed; a run takes 0.2-30 s
per mesh on this machine, so its parts are cached on disk keyed by a hash of the vertices and triangles.
Without ``coacd`` (or with ``method="hull"``) the object is its single convex hull. ``method="auto"`` (the
default) decomposes only what is not nearly convex: a mesh whose closed volume is at least
``SOLIDITY_FOR_HULL`` of its hull's (the HOPE boxes 0.94-0.97, cans 0.84: rims and seams) is its hull; a mug
or a bowl (well below) is decomposed.

``coacd`` is imported lazily, *after* open3d: importing it first breaks open3d's import in the same
process (``ImportError: std::bad_cast``, seen with coacd 1.0.14 and open3d 0.20).
"""

from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull

from services.sim.errors import SimInputError

#: Parameters of the coacd run (part of the cache key): a loose concavity threshold and few parts keep
#: the decomposition fast and the contact count low; grasp contact needs the faces, not the fine detail.
COACD_PARAMS = {"threshold": 0.1, "max_convex_hull": 8, "preprocess_resolution": 30, "resolution": 1000,
                "mcts_iterations": 60, "mcts_max_depth": 2, "mcts_nodes": 10, "seed": 0}
#: Volume / hull volume at or above which ``method="auto"`` uses the hull alone.
SOLIDITY_FOR_HULL = 0.8
_lock = threading.Lock()
_memory: dict[str, list[np.ndarray]] = {}


def cache_dir() -> Path:
    """``$OBJSCAN_CACHE_DIR/collision`` or ``$XDG_CACHE_HOME/objscan/collision`` (``~/.cache``)."""
    base = os.environ.get("OBJSCAN_CACHE_DIR")
    if base:
        return Path(base) / "collision"
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "objscan" / "collision"


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (what MuJoCo would use for a mesh geom)."""
    pts = np.asarray(points, dtype=np.float64)
    return pts[ConvexHull(pts).vertices]


def have_coacd() -> bool:
    """Whether the decomposition package can be imported here."""
    try:
        import coacd  # noqa: F401
    except ImportError:
        return False
    return True


def solidity(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """|closed mesh volume| / convex hull volume (divergence theorem; an open mesh gives a rough value)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    vol = abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)
    hull = ConvexHull(v).volume
    return vol / hull if hull > 0 else 0.0


def convex_parts(vertices: np.ndarray, triangles: np.ndarray, method: str = "auto",
                 params: dict | None = None) -> tuple[list[np.ndarray], str]:
    """Convex parts (each an (n, 3) array of hull vertices, object frame) and the method that made them.

    ``method`` is "auto" (hull when nearly convex, else coacd), "coacd" (falls back to "hull" when coacd
    is not installed) or "hull". ``params`` replaces ``COACD_PARAMS`` (the export asks for tighter parts).
    """
    params = dict(COACD_PARAMS if params is None else params)
    if method not in ("auto", "coacd", "hull"):
        raise SimInputError(f"collision method must be 'auto', 'coacd' or 'hull', got {method!r}", code="bad_value")
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    t = np.ascontiguousarray(triangles, dtype=np.int32)
    if method == "auto":
        method = "hull" if solidity(v, t) >= SOLIDITY_FOR_HULL else "coacd"
    if method == "hull" or not have_coacd():
        return [hull_vertices(v)], "hull"
    key = hashlib.sha256(v.tobytes() + t.tobytes() + repr(sorted(params.items())).encode()).hexdigest()[:24]
    with _lock:
        if key in _memory:
            return [p.copy() for p in _memory[key]], "coacd"
        path = cache_dir() / f"coacd-{key}.npz"
        parts = _load(path)
        if parts is None:
            parts = _run_coacd(v, t, params)
            _save(path, parts)
        _memory[key] = parts
        return [p.copy() for p in parts], "coacd"


def _run_coacd(v: np.ndarray, t: np.ndarray, params: dict) -> list[np.ndarray]:
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(v, t), **params)
    out = []
    for pv, _ in parts:
        pv = np.asarray(pv, dtype=np.float64)
        if len(pv) >= 4 and np.ptp(pv, axis=0).min() > 1e-5:
            out.append(hull_vertices(pv))
    return out or [hull_vertices(v)]


def _load(path: Path) -> list[np.ndarray] | None:
    try:
        with np.load(path) as z:
            return [z[k] for k in sorted(z.files, key=lambda s: int(s[1:]))]
    except (OSError, ValueError, KeyError):
        return None


def _save(path: Path, parts: list[np.ndarray]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez(tmp, **{f"p{i}": p for i, p in enumerate(parts)})
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache only costs the next run the decomposition again

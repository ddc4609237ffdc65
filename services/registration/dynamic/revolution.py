"""Is a view a body of revolution about the turn axis? Then its turn comes from the prior.

Why: the yaw about a body of revolution's own axis cannot be seen in its shape (a cylinder, a bottle, a cup
whose handle is out of view), nor in colour bands that are the same all round. The pair's local refinement
then follows the overlap of the two partial views, which is largest when the views lie on top of each other:
on the harsh twin's cylinder every edge ended ~30 degrees from its commanded turn (no turn at all), the views
were stacked on one side and the model was a partial arc. Where the shape and the colours cannot tell the
turn, the commanded turn (the pair's prior) is the best estimate there is: its error is the turn accuracy
(a few degrees), which on a surface of revolution moves no point off the surface.

The test: the object's axis is fitted from the cloud (a circle per horizontal slice about the table normal;
the axis passes through their median centre), and the view is a body of revolution when nearly all of its
normals lie in their meridian planes (the plane through the axis and the point: a surface of revolution's normal
has no component along the turn). A box's faces, a handle in view, a drill's grip have many that do not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RevolutionConfig:
    """When a view counts as a body of revolution (see the module doc); ``enabled=False`` never."""

    enabled: bool = True
    slice_m: float = 0.005  # height of one slice of the cloud along the axis
    min_slice_points: int = 30  # a slice with fewer points gets no circle
    min_slices: int = 4  # fewer fitted slices: no verdict (not a body of revolution)
    min_radius_m: float = 0.005  # points this near the axis have no meaningful turn direction
    max_normal_turn_deg: float = 20.0  # a normal this close to its meridian plane fits a surface of revolution
    min_on_surface: float = 0.9  # share of the points that must fit it
    probe_deg: float = 15.0  # the colour test: the pair turned this much either way about the fitted axis ...
    max_colour_rise: float = 0.02  # ... changes the mean chromaticity difference by no more than this
    polish: bool = True  # after the turn: one point-to-plane pass for tilt and shift, its yaw put back


@dataclass
class Revolution:
    """The fitted axis (a point on it; the direction is the turn axis) and how well the cloud fits it."""

    point: np.ndarray
    on_surface: float  # share of the points whose normal fits a surface of revolution about the axis
    slices: int

    def to_json(self) -> dict:
        return {"axis_point": [round(float(x), 5) for x in self.point], "on_surface": round(self.on_surface, 4),
                "slices": self.slices}


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares circle through 2-D points (algebraic fit): (centre, radius)."""
    A = np.column_stack([2.0 * xy, np.ones(len(xy))])
    b = np.sum(xy * xy, axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:2]
    return c, float(np.sqrt(max(sol[2] + c @ c, 0.0)))


def fit_revolution(xyz: np.ndarray, normals: np.ndarray, axis: np.ndarray, origin: np.ndarray,
                   config: RevolutionConfig | None = None) -> Revolution | None:
    """The surface of revolution about ``axis`` that best fits ``xyz`` (None: too few slices to tell)."""
    cfg = config or RevolutionConfig()
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    p = np.asarray(xyz, dtype=float) - np.asarray(origin, dtype=float)
    h, xy = p @ a, np.column_stack([p @ u, p @ v])
    bins = np.floor((h - h.min()) / cfg.slice_m).astype(int) if len(h) else np.zeros(0, int)
    centres, members = [], []
    for b in np.unique(bins):
        idx = np.flatnonzero(bins == b)
        if len(idx) >= cfg.min_slice_points:
            centres.append(_circle(xy[idx])[0])
            members.append(idx)
    if len(centres) < cfg.min_slices:
        return None
    c = np.median(np.asarray(centres), axis=0)  # one axis for the object: the slices' median centre
    # on a surface of revolution every normal lies in its meridian plane (no component along the turn)
    radial = xy - c
    r = np.linalg.norm(radial, axis=1)
    far = r > cfg.min_radius_m
    tangent = np.column_stack([-radial[:, 1], radial[:, 0]]) / np.maximum(r, 1e-9)[:, None]
    n = np.asarray(normals, dtype=float)
    n2 = np.column_stack([n @ u, n @ v])
    along = np.abs(np.sum(n2 * tangent, axis=1)) / np.maximum(np.linalg.norm(n, axis=1), 1e-9)
    on = int(np.sum(along[far] <= np.sin(np.radians(cfg.max_normal_turn_deg))))
    point = np.asarray(origin, dtype=float) + c[0] * u + c[1] * v
    return Revolution(point, on / max(int(far.sum()), 1), len(centres))


def is_revolution(fit: Revolution | None, config: RevolutionConfig | None = None) -> bool:
    cfg = config or RevolutionConfig()
    return cfg.enabled and fit is not None and fit.on_surface >= cfg.min_on_surface

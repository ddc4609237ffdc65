"""Which scan corrections the arm's accuracy can explain: the window every static result must fall in.

A scan's registration corrects the arm's relative pose (scan j against scan 0). Both camera poses are off
by about the arm's sigma (position ``sp``, orientation ``sr``), independently, and scan 0's orientation error
also swings the baseline ``b`` between the two cameras, so the correction stays within

    translation: k * sqrt(2 * sp^2 + (sr * b)^2),   rotation: k * sqrt(2) * sr

with ``k = plausible_sigmas`` (5 by default), never below the floors (a perfect arm would otherwise reject the
registration's own noise). A result beyond that is rejected however well it fits: a symmetric box fits
itself turned by 90 degrees, and no arm is 90 degrees or 40 cm off the pose it was commanded to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.geometry import transform_error

from .config import StaticConfig


@dataclass(frozen=True)
class Bound:
    """The largest plausible correction of one relative pose (m, deg)."""

    m: float
    deg: float

    def admits(self, dt_m: float, dr_deg: float) -> bool:
        return dt_m <= self.m and dr_deg <= self.deg

    def to_json(self) -> dict[str, float]:
        return {"mm": round(self.m * 1e3, 2), "deg": round(self.deg, 3)}


def correction_bound(prior: np.ndarray, cfg: StaticConfig) -> Bound:
    """The plausibility bound for a correction of ``prior`` (T_ci_cj, the arm's relative pose)."""
    k = cfg.plausible_sigmas
    sp = cfg.arm_position_sigma_mm * 1e-3
    sr = math.radians(cfg.arm_orientation_sigma_deg)
    baseline = float(np.linalg.norm(np.asarray(prior)[:3, 3]))
    m = k * math.sqrt(2.0 * sp * sp + (sr * baseline) ** 2)
    deg = k * math.sqrt(2.0) * cfg.arm_orientation_sigma_deg
    return Bound(m=max(m, cfg.plausible_floor_mm * 1e-3), deg=max(deg, cfg.plausible_floor_deg))


def implausibility(T: np.ndarray, prior: np.ndarray, cfg: StaticConfig) -> str | None:
    """Why ``T`` is not a correction the arm can explain, or None when it is."""
    bound = correction_bound(prior, cfg)
    dt, dr = transform_error(T, prior)
    if bound.admits(dt, dr):
        return None
    return (f"implausible: {dt * 1e3:.1f} mm / {dr:.2f} deg from the arm's pose, beyond the "
            f"{bound.m * 1e3:.1f} mm / {bound.deg:.2f} deg its accuracy allows")


def plausible(T: np.ndarray, prior: np.ndarray, cfg: StaticConfig) -> bool:
    return implausibility(T, prior, cfg) is None

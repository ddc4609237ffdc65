"""Normals that point out of the object: towards the scans that saw each point.

The point model's normals are fitted to the neighbourhood of each point and carry no sign. Screened
Poisson needs them outward, everywhere: one inward normal patch makes it wrap a sheet of surface around
the wrong side. Away from the object's vertical axis is outward on a box or a can's side, but not on the
inner wall of a can's rim around its recessed lid, which faces the axis: turned away from it, Poisson
closed the lid with a dome above the rim (5 mm high on a 66 mm can, about 8 % of its volume). A surface seen
by a camera faces that camera, so each normal takes the sign that turns it towards the scans that saw its
point (``visibility.seen_by``); a point no scan saw keeps the away-from-the-axis rule.
"""

from __future__ import annotations

import numpy as np

from services.export.inputs import PosedFrame
from services.export.visibility import camera_in_object, seen_by


def orient_outward(xyz: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Normals flipped to point away from the object's vertical axis (through the points' centroid).

    Outward for objects star-shaped about their vertical axis (boxes, cans, bottles); top faces (normals
    nearly vertical) point up, bottom faces down. The fallback for points no scan saw.
    """
    n = np.array(normals, dtype=np.float64, copy=True)
    c = xyz.mean(axis=0)
    radial = xyz - c
    radial[:, 2] = 0.0
    vertical = np.abs(n[:, 2]) > 0.9
    up_wanted = np.where(xyz[:, 2] > c[2], 1.0, -1.0)
    out = np.where(vertical, np.sign(n[:, 2]) * up_wanted, np.sign(np.einsum("ij,ij->i", n, radial)))
    n[out < 0] *= -1.0
    return n


def orient_to_cameras(xyz: np.ndarray, normals: np.ndarray, frames: list[PosedFrame],
                      T_object_model: np.ndarray) -> tuple[np.ndarray, int]:
    """Object-frame normals turned towards the scans that saw their points; (normals, points no scan saw).

    Each scan that saw a point votes with the side its camera is on (cosine-weighted, so a grazing view
    counts little); points without a vote fall back to ``orient_outward``.
    """
    n = np.asarray(normals, dtype=np.float64)
    vote = np.zeros(len(xyz))
    for pf in frames:
        T_object_camera = camera_in_object(pf, T_object_model)
        seen = seen_by(xyz, pf, T_object_camera)
        if not seen.any():
            continue
        ray = T_object_camera[:3, 3] - xyz[seen]
        ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-12)
        vote[seen] += np.einsum("ij,ij->i", n[seen], ray)
    out = orient_outward(xyz, n)
    voted = vote != 0.0
    out[voted] = n[voted] * np.sign(vote[voted])[:, None]
    return out, int((~voted).sum())

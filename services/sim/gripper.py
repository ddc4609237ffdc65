"""The parallel-jaw gripper of the twin (RH-P12-RN-like) and the geometric test of a grasp.

Gripper frame (docs/conventions.md): x = approach, y = across the fingers (closing direction), z = up for
a horizontal approach; the TCP is midway between the pads. A grasp is *sound* when, with the fingers
open as they approached, neither pad is inside the object or below the table top, the object's surface
lies between the pads, it is narrower than the opening and wider than the commanded closing, and both
pads get a real contact patch (surface facing the pad within 50°, within ``contact_tolerance`` of the
pad, of at least ``min_contact_area``). The gripper closes symmetrically, so an off-centre object is pushed onto
the gripper's centre line as it closes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from common.geometry import transform_points


@dataclass(frozen=True)
class GripperSpec:
    """Finger pad geometry in the gripper frame (m). Defaults: ROBOTIS RH-P12-RN(A) on PAPRAS.

    Pad sizes match ``services/grasp/config.py`` (bounding boxes of the RH-P12-RN distal links). The TCP
    (``gripper`` frame of the arm's URDF) is midway between the pads *fully closed*; the parallel linkage
    pulls the pads back along the approach as they open: ``retraction`` is that pull-back against the
    opening, measured on the URDF linkage with pinocchio (pad point 20 mm up the distal link).
    """

    max_opening: float = 0.106  # RH-P12-RN(A) stroke
    pad_length: float = 0.040  # along x (approach)
    pad_height: float = 0.026  # along z
    pad_thickness: float = 0.022  # along y
    retraction_openings: tuple[float, ...] = (0.0, 0.02, 0.04, 0.06, 0.073, 0.09, 0.106)
    retraction: tuple[float, ...] = (0.0, 0.0004, 0.0025, 0.0065, 0.0103, 0.0173, 0.0273)
    contact_tolerance: float = 0.003  # surface within this of a pad counts as touching it
    min_contact_area: float = 2.0e-5  # m^2 (20 mm^2) of pad-facing surface needed under each pad
    table_clearance: float = 0.0  # pads must stay above z = table_clearance in base

    def pad_center_x(self, opening: float) -> float:
        """x of the pad centres in the gripper frame when the fingers are ``opening`` apart."""
        return -float(np.interp(opening, self.retraction_openings, self.retraction))


@dataclass(frozen=True)
class GraspOutcome:
    """What closing the gripper achieved. ``reason`` is a stable code: "ok", "already_holding",
    "pad_hits_table", "nothing_between_pads", "too_wide", "pad_collides_with_object",
    "pads_stop_before_contact", "insufficient_contact", "slip"."""

    success: bool
    reason: str
    width: float  # opening the gripper reports after closing (m)
    message: str = ""

    def to_dict(self) -> dict:
        return {"success": self.success, "reason": self.reason, "width": self.width, "message": self.message}


@dataclass(frozen=True)
class GraspContact:
    """The geometric part of a sound grasp: object width between the pads and the centring push along
    the gripper's y (the object moves by ``-center_offset_y`` as the symmetric fingers close)."""

    width: float
    center_offset_y: float


def pad_boxes(spec: GripperSpec, opening: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(min corner, max corner) of both pads in the gripper frame at ``opening``."""
    half = opening / 2.0
    cx = spec.pad_center_x(opening)
    x0, x1 = cx - spec.pad_length / 2, cx + spec.pad_length / 2
    z0, z1 = -spec.pad_height / 2, spec.pad_height / 2
    return [(np.array([x0, half, z0]), np.array([x1, half + spec.pad_thickness, z1])),
            (np.array([x0, -half - spec.pad_thickness, z0]), np.array([x1, -half, z1]))]


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _box_grid(lo: np.ndarray, hi: np.ndarray, n: int = 4) -> np.ndarray:
    axes = [np.linspace(lo[i], hi[i], n) for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


class GraspChecker:
    """Evaluates grasps against one object: dense surface samples plus an occupancy scene of its mesh,
    both in the object frame, built once."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, surface_points: np.ndarray,
                 surface_normals: np.ndarray, surface_area: float, spec: GripperSpec | None = None):
        self.spec = spec = spec or GripperSpec()
        self.points = np.asarray(surface_points, dtype=np.float64)
        self.normals = np.asarray(surface_normals, dtype=np.float64)
        self.area_per_point = float(surface_area) / max(len(self.points), 1)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(np.asarray(vertices, dtype=np.float32)),
                                  o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))

    def _inside(self, pts_object: np.ndarray) -> np.ndarray:
        occ = self._scene.compute_occupancy(o3d.core.Tensor(pts_object.astype(np.float32)), nsamples=5)
        return occ.numpy() > 0.5

    def _slab(self, p: np.ndarray, in_pad_band: np.ndarray, facing: np.ndarray,
              opening: float) -> tuple[np.ndarray, np.ndarray]:
        """Surface samples (gripper frame) in the region the pads sweep when ``opening`` apart, and
        whether each faces the pads."""
        cx = self.spec.pad_center_x(opening)
        sel = in_pad_band & (np.abs(p[:, 0] - cx) <= self.spec.pad_length / 2)
        return p[sel], facing[sel]

    def evaluate(self, T_object_gripper: np.ndarray, T_base_gripper: np.ndarray, opening: float,
                 opening_cmd: float) -> tuple[GraspOutcome, GraspContact | None]:
        """Test the grasp at ``T_object_gripper`` with the fingers open at ``opening`` closing towards
        ``opening_cmd``; ``T_base_gripper`` is used for the table check. Returns the outcome and, when
        sound, the contact geometry."""
        spec = self.spec
        opening = float(np.clip(opening, 0.0, spec.max_opening))
        opening_cmd = float(np.clip(opening_cmd, 0.0, opening))
        boxes = pad_boxes(spec, opening)
        corners = np.vstack([_box_corners(lo, hi) for lo, hi in boxes])
        z_base = transform_points(T_base_gripper, corners)[:, 2]
        if z_base.min() < spec.table_clearance:
            return GraspOutcome(False, "pad_hits_table", opening_cmd,
                                f"a finger pad reaches {z_base.min() * 1000:.1f} mm below the table top"), None

        T_gripper_object = np.linalg.inv(T_object_gripper)
        p = transform_points(T_gripper_object, self.points)
        # how squarely each surface sample faces the pads (|n . y|): only such surface can bear on a pad
        facing_all = np.abs(self.normals @ T_gripper_object[:3, :3][1]) > np.cos(np.radians(50.0))
        in_pad_band = np.abs(p[:, 2]) <= spec.pad_height / 2
        slab, _ = self._slab(p, in_pad_band, facing_all, opening)
        half = opening / 2.0

        # pads inside the object's volume or cutting its surface: the fingers would have hit it
        pad_pts = np.vstack([_box_grid(lo, hi) for lo, hi in boxes])
        cuts = np.zeros(len(slab), dtype=bool)
        for lo, hi in boxes:
            cuts |= np.all((slab >= lo) & (slab <= hi), axis=1)
        if cuts.any() or self._inside(transform_points(T_object_gripper, pad_pts)).any():
            span = float(np.ptp(slab[:, 1])) if len(slab) else 0.0
            if span > spec.max_opening:
                return GraspOutcome(False, "too_wide", opening_cmd,
                                    f"the object is {span * 1000:.0f} mm across between the pads, the gripper opens "
                                    f"{spec.max_opening * 1000:.0f} mm"), None
            return GraspOutcome(False, "pad_collides_with_object", opening_cmd,
                                f"a finger pad opened to {opening * 1000:.0f} mm is inside the object"), None

        # the pads move forward as they close: a surface point at |y| is swept by the pad when the fingers
        # are 2|y| apart, so it is within reach if the pad's x range at that opening covers it
        ay = np.abs(p[:, 1])
        cx_at = -np.interp(np.minimum(2 * ay, opening), spec.retraction_openings, spec.retraction)
        reach = in_pad_band & (np.abs(p[:, 0] - cx_at) <= spec.pad_length / 2) & (ay < half)
        if not reach.any():
            return GraspOutcome(False, "nothing_between_pads", opening_cmd,
                                "no part of the object lies between the finger pads"), None
        width = float(np.ptp(p[reach, 1]))
        # then settle where the closed pads end up (their x depends on the width they stop at)
        for _ in range(3):
            slab, facing = self._slab(p, in_pad_band, facing_all, width)
            inside = np.abs(slab[:, 1]) < half
            between, facing = slab[inside], facing[inside]
            if len(between) == 0:
                return GraspOutcome(False, "nothing_between_pads", opening_cmd,
                                    "no part of the object lies between the finger pads"), None
            y_min, y_max = float(between[:, 1].min()), float(between[:, 1].max())
            if abs((y_max - y_min) - width) < 1e-4:
                break
            width = y_max - y_min
        if width <= opening_cmd:
            return GraspOutcome(False, "pads_stop_before_contact", opening_cmd,
                                f"the object is {width * 1000:.1f} mm wide, the gripper stops at "
                                f"{opening_cmd * 1000:.1f} mm"), None
        tol = spec.contact_tolerance
        area_lo = float(np.count_nonzero(facing & (between[:, 1] <= y_min + tol))) * self.area_per_point
        area_hi = float(np.count_nonzero(facing & (between[:, 1] >= y_max - tol))) * self.area_per_point
        if min(area_lo, area_hi) < spec.min_contact_area:
            return GraspOutcome(False, "insufficient_contact", opening_cmd,
                                f"contact patches of {area_lo * 1e6:.0f} and {area_hi * 1e6:.0f} mm^2, need "
                                f"{spec.min_contact_area * 1e6:.0f} mm^2 under each pad"), None
        return (GraspOutcome(True, "ok", width, f"holding {width * 1000:.1f} mm between the pads"),
                GraspContact(width=width, center_offset_y=(y_min + y_max) / 2.0))

"""Collision filtering of a grasp (paper II-B.3): table box, gripper-pad boxes, and the object cloud.

- Table box (frontal): 0.5 m square, 0.025 m high, its top face on the table plane under the object's
  footprint centre. Top-down: the rest of the object below the top crop, limited to the object's
  footprint (when the crop holds the whole object there is nothing below it to hit).
- Pad boxes: oriented like the gripper at the grasp, the size of the physical pads, one beyond each
  contact along the grasp line with the inner face ``pad_gap``/2 outside the contact.
- Palm box (frontal, optional, not in the paper): the palm behind the fingers at contact height; it
  is what actually stops a low frontal grasp.
Pads and palm tested against the table box use the separating-axis test, inflated by the table
clearance; pads are tested against the object points themselves.
"""

from __future__ import annotations

import numpy as np

from services.grasp.boxes import OrientedBox, boxes_overlap, orthonormal_frame_from_axis
from services.grasp.config import GraspPlannerConfig


def table_box(points: np.ndarray, up: np.ndarray, plane_offset: float, size: float, height: float
              ) -> OrientedBox:
    """Box of ``size`` x ``size`` x ``height`` whose top face is the table plane under the object.

    The centre is the object's mean projected on the plane, then half the height down.
    """
    mean = np.asarray(points, float).mean(axis=0)
    on_plane = mean - (mean @ up + plane_offset) * up
    return OrientedBox.from_extents(on_plane - 0.5 * height * up, orthonormal_frame_from_axis(up),
                                    np.array([height, size, size]))


def remainder_box(heights: np.ndarray, crop_bottom: float, up: np.ndarray, plane_offset: float,
                  footprint: OrientedBox) -> OrientedBox | None:
    """Top-down 'table': the object below ``crop_bottom`` as a box spanning the footprint's horizontal
    extent, from the lowest object point up to the crop; None when no point lies below the crop.

    ``heights`` are the points' signed distances to the table (n·p + offset); ``footprint`` is a box
    with one axis along ``up`` (the object's table-aligned box).
    """
    below = heights < crop_bottom
    if not np.any(below):
        return None
    h_lo = float(heights[below].min())
    R = footprint.rotation
    vertical = int(np.argmax(np.abs(R.T @ up)))
    extents = 2.0 * footprint.half_extents.copy()
    extents[vertical] = crop_bottom - h_lo
    c = footprint.center
    c_height = float(c @ up + plane_offset)
    center = c + (0.5 * (h_lo + crop_bottom) - c_height) * up
    return OrientedBox.from_extents(center, R, extents)


def pad_boxes(R: np.ndarray, p_plus: np.ndarray, p_minus: np.ndarray, cfg: GraspPlannerConfig,
              back: float = 0.0) -> tuple[OrientedBox, OrientedBox]:
    """The two pad boxes of a grasp whose gripper rotation is ``R`` (y from ``p_minus`` to ``p_plus``).

    Centred on the contacts along the approach, or ``back`` metres behind them (top-down grasps on a
    low object: the fingertips stop above the table, so the pads sit higher than the contacts).
    """
    g = cfg.gripper
    y = R[:, 1]
    shift = 0.5 * g.pad_thickness + 0.5 * cfg.pad_gap
    ext = np.array(g.pad_extents)
    along = -back * R[:, 0]
    return (OrientedBox.from_extents(p_plus + shift * y + along, R, ext),
            OrientedBox.from_extents(p_minus - shift * y + along, R, ext))


def palm_box(R: np.ndarray, tcp: np.ndarray, cfg: GraspPlannerConfig) -> OrientedBox:
    """The palm, ``finger_length`` behind the TCP along the approach."""
    g = cfg.gripper
    center = tcp - (g.finger_length + 0.5 * g.palm_depth) * R[:, 0]
    return OrientedBox.from_extents(center, R, np.array(g.palm_extents))


def inflate(box: OrientedBox, margin: float) -> OrientedBox:
    return OrientedBox(box.center, box.rotation, box.half_extents + margin)


def first_overlap(boxes: dict[str, OrientedBox], obstacle: OrientedBox, margin: float) -> str | None:
    """Name of the first box that overlaps ``obstacle`` once inflated by ``margin``; None when clear."""
    for name, box in boxes.items():
        if boxes_overlap(inflate(box, margin), obstacle):
            return name
    return None

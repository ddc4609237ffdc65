"""The contacts of a grasp near the gripper's stroke (``common.stroke``): on the faces, on a level line.

A GeoGrasp pair is two points of the cloud. Far from the stroke that is all a grasp needs. Near it (a 9.9 cm
box in a 10.6 cm stroke leaves the open pads 3.5 mm a side) two things a single point carries matter:
- its depth noise (about 1 mm on a D435 at 0.4 m): the grasp centre is off by up to half the two points'
  noise, on top of the camera's location error. The face's points about each contact, not the one point,
  say where the face is (``contacts_on_faces``);
- its height: two contacts at different heights on upright faces tilt the grasp line, and the pads with it,
  against the faces (``level_contacts``). Measured on the 9.9 cm box: contacts 8 mm apart in height tilted
  the line 4.6 degrees and a pad corner cut the face by 1 mm.
"""

from __future__ import annotations

import numpy as np

from common.stroke import near_stroke

#: m around a contact whose face points place the face.
FACE_RADIUS = 0.01
#: a point belongs to the contact's face when its normal is within this angle of the contact's (either sign)
FACE_ANGLE_DEG = 30.0
#: a grasp line steeper than this is the object's shape, not two contacts' noise, and is left as it is
MAX_LEVELLED_TILT_DEG = 15.0


def level_contacts(p1: np.ndarray, p2: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``p1``, ``p2`` moved along ``up`` to their mean height: the grasp line made parallel to the table,
    when it is within ``MAX_LEVELLED_TILT_DEG`` of it. On an upright face the contacts stay on the face."""
    p1, p2 = np.asarray(p1, float), np.asarray(p2, float)
    up = np.asarray(up, float) / np.linalg.norm(up)
    line = p1 - p2
    dz = float(line @ up)
    if abs(dz) > np.sin(np.radians(MAX_LEVELLED_TILT_DEG)) * float(np.linalg.norm(line)):
        return p1, p2
    return p1 - 0.5 * dz * up, p2 + 0.5 * dz * up


def contacts_on_faces(xyz: np.ndarray, normals: np.ndarray, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Contacts ``i`` and ``j`` of ``xyz`` moved along their grasp line onto the median plane of their faces'
    points within ``FACE_RADIUS`` (normals within ``FACE_ANGLE_DEG`` of the contact's)."""
    xyz, normals = np.asarray(xyz, float), np.asarray(normals, float)
    line = xyz[i] - xyz[j]
    y = line / np.linalg.norm(line)
    cos_face = np.cos(np.radians(FACE_ANGLE_DEG))
    out = []
    for k in (i, j):
        near = np.linalg.norm(xyz - xyz[k], axis=1) < FACE_RADIUS
        face = near & (np.abs(normals @ normals[k]) > cos_face)
        offset = float(np.median((xyz[face] - xyz[k]) @ y)) if np.count_nonzero(face) >= 3 else 0.0
        out.append(xyz[k] + offset * y)
    return out[0], out[1]


def near_stroke_contacts(xyz: np.ndarray, normals: np.ndarray, i: int, j: int, up: np.ndarray, stroke: float,
                         side: float) -> tuple[np.ndarray, np.ndarray]:
    """The contacts of pair (``i``, ``j``) as the hand takes them: the two points themselves, or, when the
    grasp is near the stroke (the open pads clear it by under ``side`` a side) and closes on two faces
    (``square_to_faces``), on their faces and level."""
    p1, p2 = np.asarray(xyz[i], float), np.asarray(xyz[j], float)
    if not near_stroke(float(np.linalg.norm(p1 - p2)), stroke, side) or not square_to_faces(normals, i, j, p1 - p2):
        return p1, p2
    return level_contacts(*contacts_on_faces(xyz, normals, i, j), up)


def square_to_faces(normals: np.ndarray, i: int, j: int, line: np.ndarray) -> bool:
    """Whether both contacts' normals lie within ``FACE_ANGLE_DEG`` of the grasp ``line``: the pads close on two
    faces. A pair from an edge keeps its two points: its faces do not say where the pads meet the object (settled
    on them, the 9.96 cm edge pair of a 9.3 cm box moved its pads into the box)."""
    n = np.asarray(normals, float)
    u = np.asarray(line, float) / max(float(np.linalg.norm(line)), 1e-12)
    cos_face = np.cos(np.radians(FACE_ANGLE_DEG))
    return bool(abs(float(n[i] @ u)) >= cos_face and abs(float(n[j] @ u)) >= cos_face)

"""Scripted twin scans without services: the input of the benchmarks (``objscan bench``), no arm, just the twin.

``simulated_views`` does what an acquisition does to the object, minus the grasping: for each view it
scans the object from a few camera poses around its front, then a person turns it by 30° (with the
profile's turn and placement errors) before the next view. Frames carry the commanded cumulative turn and
the true object pose, so static and dynamic registration can be tested and benchmarked against ground
truth; ``write_session`` stores them as a session folder (common/session_folder.py).

Scan poses are planned as a real cell plans them: from where the object is *estimated* to be, never from
the truth. View 0 is planned from a locate frame looking at where the object is expected; every later
view from the previous view's first scan; each estimate is the static stage's object centre and height
(``services.registration.static``), as the orchestrator's. With the ``realistic`` profile the object is
off the expected spot by up to 3 cm and the believed camera poses are off by millimetres, so the scans
are aimed off-centre as they would be in a real cell.

Deterministic for a seed: the same call gives byte-identical images.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.geometry import look_at
from common.messages import Intrinsics, RGBDFrame, d435_intrinsics
from common.session_folder import write_scan
from common.session_folder import write_session as write_session_json
from services.sim.errors import SimInputError
from services.sim.profiles import PROFILES, ErrorProfile, get_profile, hand_turn
from services.sim.world import World, default_object_pose


@dataclass(frozen=True)
class ScanPoses:
    """Camera poses of one view: on a sphere around the object's centre, spread around its front (the
    side facing the robot base, azimuth 180° in base), looking at the centre."""

    distances_m: tuple[float, ...] = (0.40, 0.38, 0.42)
    elevations_deg: tuple[float, ...] = (40.0, 32.0, 48.0)
    azimuth_offsets_deg: tuple[float, ...] = (0.0, -25.0, 25.0)
    front_azimuth_deg: float = 180.0

    def poses(self, center: np.ndarray, count: int) -> list[np.ndarray]:
        """``count`` camera poses (T_base_camera, optical frame); beyond the listed ones the pattern repeats
        with the azimuth spread narrowed so no two poses coincide."""
        out = []
        n = len(self.azimuth_offsets_deg)
        for j in range(count):
            k, rnd = j % n, j // n
            az = np.radians(self.front_azimuth_deg + self.azimuth_offsets_deg[k] / (1 + rnd) + 7.0 * rnd)
            el = np.radians(self.elevations_deg[k % len(self.elevations_deg)])
            d = self.distances_m[k % len(self.distances_m)]
            eye = center + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
            out.append(camera_look_at(eye, center))
        return out


def camera_look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """T_base_camera (optical frame) at ``eye`` looking at ``target`` with the image upright (world up
    appears up, i.e. the camera's y axis points down)."""
    T = look_at(eye, target, (0.0, 0.0, 1.0))
    if T[2, 1] > 0:  # the image's down direction points up: roll by 180° about the optical axis
        T[:3, :2] = -T[:3, :2]
    return T


LOCATE_DISTANCE_M, LOCATE_ELEVATION_DEG = 0.45, 55.0  # the orchestrator's locate pose (ScanGeometry)
LOCATE_SEQ = 1_000_000  # locate frames' sequence numbers start here (scan frames keep 0, 1, 2, ...)


def locate_pose(expected_xy: np.ndarray, scan_poses: ScanPoses = ScanPoses()) -> np.ndarray:
    """The locate camera pose: from the front, high enough to see the table around where the object is
    expected, looking at 5 cm above the table there."""
    target = np.array([expected_xy[0], expected_xy[1], 0.05])
    el, az = np.radians(LOCATE_ELEVATION_DEG), np.radians(scan_poses.front_azimuth_deg)
    eye = target + LOCATE_DISTANCE_M * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return camera_look_at(eye, target)


def estimate_object(frame: RGBDFrame) -> tuple[np.ndarray, float] | None:
    """(footprint centre in base, height) of the object the frame looks at, by the static stage from the
    frame's *believed* pose, as the orchestrator estimates it; None when the stage finds no object."""
    from common.errors import ObjscanError
    from services.registration.api import register_view

    try:
        result = register_view([frame])
    except ObjscanError:
        return None
    return np.asarray(result.object_center, dtype=np.float64), float(result.object_height)


def simulated_views(object_name: str, *, views: int = 12, scans_per_view: int = 3,
                    profile: str | ErrorProfile = "ideal", seed: int = 0, intrinsics: Intrinsics | None = None,
                    turn_deg: float = 30.0, object_pose: np.ndarray | None = None,
                    scan_poses: ScanPoses = ScanPoses(), world: World | None = None,
                    plan_from: str = "estimate") -> list[list[RGBDFrame]]:
    """Scan ``object_name`` (HOPE name or mesh path) over ``views`` views of ``scans_per_view`` frames,
    hand-turning it by ``turn_deg`` between views.

    Returns ``frames[view][scan]``. Each frame's ``T_base_camera`` is the believed pose and
    ``T_base_camera_true`` the truth; ``meta`` holds ``view``, ``scan``, ``commanded_turn_deg`` (cumulative,
    ``turn_deg * view``), ``achieved_turn_deg_true`` (cumulative, ground truth), ``T_base_object_true``,
    ``object``, ``profile``, ``seed`` and ``planned_center`` (the point the scan poses aim at; with
    ``plan_from="estimate"``, the default, it comes from the previous view or a locate frame, see the
    module docstring; ``"truth"`` aims at the true centre, whatever the profile's errors).
    Default intrinsics: D435 640x480.
    """
    if plan_from not in ("estimate", "truth"):
        raise SimInputError("plan_from must be 'estimate' or 'truth'", code="bad_value",
                            detail={"plan_from": plan_from})
    if views < 1 or scans_per_view < 1:
        raise SimInputError("views and scans_per_view must be at least 1", code="bad_value",
                            detail={"views": views, "scans_per_view": scans_per_view})
    K = intrinsics or d435_intrinsics()
    prof = get_profile(profile)
    if world is None:
        world = World(object_name, profile=prof, seed=seed,
                      object_pose=default_object_pose() if object_pose is None else object_pose)
    out: list[list[RGBDFrame]] = []
    achieved_total = 0.0
    seq = 0
    expected = world.initial_pose[:2, 3]
    estimate = None
    if plan_from == "estimate":
        estimate = estimate_object(world.render_frame(locate_pose(expected, scan_poses), K, LOCATE_SEQ))
    for v in range(views):
        if v > 0:
            achieved_total += hand_turn(world, turn_deg, None)
            if plan_from == "estimate":
                estimate = estimate_object(out[-1][0]) or estimate
        if plan_from == "truth":
            center = world.true_object_pose()[:3, 3] + np.array([0.0, 0.0, world.obj.height / 2.0])
        elif estimate is None:  # nothing found yet: aim where the object is expected, 5 cm up
            center = np.array([expected[0], expected[1], 0.05])
        else:
            center = estimate[0] + np.array([0.0, 0.0, estimate[1] / 2.0])
        frames = []
        for j, T_cam in enumerate(scan_poses.poses(center, scans_per_view)):
            frame = world.render_frame(T_cam, K, seq, stamp=seq / 30.0)
            frame.meta.update({"view": v, "scan": j, "commanded_turn_deg": turn_deg * v,
                               "achieved_turn_deg_true": achieved_total, "seed": world.seed,
                               "planned_center": center.tolist()})
            frames.append(frame)
            seq += 1
        out.append(frames)
    return out


def write_session(directory: str | Path, views: list[list[RGBDFrame]], *, extra: dict[str, Any] | None = None) -> Path:
    """Write ``views`` (as returned by ``simulated_views``) as a session folder; returns its path.

    session.json holds ``object``, ``profile``, ``seed``, ``source: "sim"`` and ``views`` with each view's
    cumulative ``commanded_turn_deg`` and, in a ``ground_truth`` block, the true object pose and turn; the
    top-level ``ground_truth.object_model`` says which mesh (path, scale, up axis) to evaluate against.
    """
    if not views or not views[0]:
        raise SimInputError("no frames to write", code="bad_value")
    session = Path(directory)
    session.mkdir(parents=True, exist_ok=True)
    first = views[0][0].meta
    entries = []
    for k, frames in enumerate(views):
        for j, frame in enumerate(frames):
            write_scan(session, k, j, frame)
        meta = frames[0].meta
        entries.append({
            "index": k,
            "commanded_turn_deg": float(meta.get("commanded_turn_deg", 0.0)),
            "scans": len(frames),
            "ground_truth": {"T_base_object": np.asarray(meta.get("T_base_object_true")).tolist()
                             if meta.get("T_base_object_true") is not None else None,
                             "achieved_turn_deg": meta.get("achieved_turn_deg_true")},
        })
    data = {"object": first.get("object"), "profile": first.get("profile"), "seed": first.get("seed"),
            "source": "sim", "views": entries, "ground_truth": {"object_model": first.get("object_model")}}
    if isinstance(first.get("profile"), str) and first["profile"] in PROFILES:  # what the twin's arm states
        data["pose_accuracy"] = PROFILES[first["profile"]].pose_accuracy().to_dict()
        data["turn_accuracy_deg"] = PROFILES[first["profile"]].turn_accuracy_deg()
    if extra:
        data.update(extra)
    write_session_json(session, data)
    return session

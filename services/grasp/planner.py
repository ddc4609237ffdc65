"""GeoGrasp-style grasp planning for the turn step (paper II-B): frontal first, top-down as fallback.

Input: an isolated object cloud with normals in ``base`` and the table plane. Output: a
:class:`GraspPlan` with the surviving grasps (best first, each with its ranking terms and named poses)
and the reasons the other candidates were dropped.

Pipeline: table-aligned box → a side face the scan poses could not see mirrored in from the seen one
(completion.py), then per variant: central slice → candidate regions at both ends of the horizontal
region axes → all-pairs GeoGrasp ranking → collision filter (table or object-below box, pad boxes,
object points, inferred ones included) → poses. When that leaves no grasp and the object stands round on
a vertical axis, the arc of wall no scan pose saw is filled about that axis (revolve.py) and the variants
run again on the observed cloud plus that arc. Everything after the first masks works on a few
thousand points at most, so a 20k-point cloud plans in milliseconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from common.messages import Plane, PointCloud
from common.stroke import near_stroke
from services.grasp.boxes import OrientedBox
from services.grasp.candidates import ObjectFrame, candidate_regions, object_frame
from services.grasp.circle import estimate_object_center
from services.grasp.collision import (
    first_overlap,
    pad_boxes,
    palm_box,
    remainder_box,
    table_box,
)
from services.grasp.completion import complete_hidden_sides, horizontal_axes
from services.grasp.config import GraspPlannerConfig
from services.grasp.errors import GraspInputError
from services.grasp.near_stroke import near_stroke_contacts, square_to_faces
from services.grasp.pitch import pitch_poses
from services.grasp.poses import frontal_rotation, grasp_poses, top_down_rotation
from services.grasp.ranking import RankedPair, rank_region_pair
from services.grasp.result import GraspPlan, PlannedGrasp, Rejections
from services.grasp.revolve import fit_vertical_axis, revolve_unseen_arc
from services.grasp.roll import roll_poses, round_section
from services.grasp.stray import stray_mask

MIN_POINTS = 10


@dataclass(frozen=True)
class PlanningInput:
    """Validated inputs: float64 points, unit normals, an upward unit table normal and its offset.

    Rows from ``n_observed`` on are inferred (mirrored in by the completion step); None = all observed.
    """

    xyz: np.ndarray
    normals: np.ndarray
    up: np.ndarray
    offset: float
    heights: np.ndarray
    n_observed: int | None = None

    def inferred(self, indices: np.ndarray | list[int]) -> int:
        """How many of the cloud rows ``indices`` are inferred points."""
        if self.n_observed is None:
            return 0
        return int(np.count_nonzero(np.asarray(indices) >= self.n_observed))


def validate_inputs(cloud_xyz: Any, normals: Any, table: Plane) -> PlanningInput:
    """Check shapes, finiteness and normals; orient the table normal toward the object.

    Raises :class:`GraspInputError` with a specific code instead of letting numpy fail (or, worse,
    silently plan on NaNs).
    """
    try:
        xyz = np.asarray(cloud_xyz, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GraspInputError(f"cloud is not numeric: {exc}", code="bad_shape") from None
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise GraspInputError("cloud must be an (N, 3) array", code="bad_shape",
                              detail={"shape": list(xyz.shape)})
    if len(xyz) == 0:
        raise GraspInputError("object cloud is empty", code="empty_cloud")
    if len(xyz) < MIN_POINTS:
        raise GraspInputError(f"object cloud has {len(xyz)} points, at least {MIN_POINTS} needed",
                              code="empty_cloud", detail={"n": len(xyz)})
    if normals is None:
        raise GraspInputError("normals are required (the ranking needs them)", code="missing_normals")
    try:
        nrm = np.asarray(normals, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GraspInputError(f"normals are not numeric: {exc}", code="bad_shape") from None
    if nrm.shape != xyz.shape:
        raise GraspInputError("normals must have the cloud's shape", code="bad_shape",
                              detail={"cloud": list(xyz.shape), "normals": list(nrm.shape)})
    if not (np.isfinite(xyz).all() and np.isfinite(nrm).all()):
        bad = ~np.isfinite(xyz).all(axis=1) | ~np.isfinite(nrm).all(axis=1)
        raise GraspInputError(f"{int(bad.sum())} points or normals are NaN/inf", code="non_finite",
                              detail={"n_bad": int(bad.sum()), "first": int(np.flatnonzero(bad)[0])})
    lengths = np.sqrt(np.einsum("ij,ij->i", nrm, nrm))
    if np.any(lengths < 1e-6):
        raise GraspInputError(f"{int((lengths < 1e-6).sum())} normals have zero length", code="zero_normals")
    nrm = nrm / lengths[:, None]
    try:
        up = np.asarray(table.normal, dtype=np.float64).reshape(3)
        offset = float(table.offset)
    except (AttributeError, TypeError, ValueError) as exc:
        raise GraspInputError(f"table is not a plane: {exc}", code="bad_table") from None
    norm = float(np.linalg.norm(up))
    if not (np.isfinite(up).all() and np.isfinite(offset) and norm > 1e-9):
        raise GraspInputError("table plane has a zero or non-finite normal/offset", code="bad_table")
    up, offset = up / norm, offset / norm
    heights = xyz @ up + offset
    if np.count_nonzero(heights > 0) < 0.5 * len(heights):  # the paper's sign fix: normal toward object
        up, offset, heights = -up, -offset, -heights
    return PlanningInput(xyz, nrm, up, offset, heights)


def plan_grasps(cloud_xyz: Any, normals: Any, table: Plane,
                config: GraspPlannerConfig | None = None) -> GraspPlan:
    """Plan grasps on an isolated object cloud (``base`` frame) standing on ``table``.

    ``config.mode``: 'auto' runs frontal and falls back to top-down when frontal yields nothing;
    'frontal', 'top_down' or 'both' run what they say. Returns a :class:`GraspPlan` (never raises for a
    well-formed cloud that merely has no grasp: the plan's ``rejections`` say why). An empty plan is
    planned once more without its stray returns (``drop_stray_points``, stray.py; that pass's rejections
    replace the first's only when it finds a grasp), then, on an upright round object, with its unseen arc
    filled in (``complete_round_sections``; the rejections then count both passes).
    """
    cfg = config or GraspPlannerConfig()
    t0 = time.perf_counter()
    observed = validate_inputs(cloud_xyz, normals, table)
    rejections = Rejections(max_examples=cfg.max_examples)
    attempted: list[str] = []
    timings: dict[str, float] = {}
    grasps, frame, center, n_slices, summary = _plan_cloud(observed, cfg, rejections, attempted, timings)
    if not grasps and cfg.drop_stray_points:
        stray = stray_mask(observed.xyz)
        if stray.any():  # a lone return beyond a face spoils the box frame: plan again without it
            keep = ~stray
            observed = replace(observed, xyz=observed.xyz[keep], normals=observed.normals[keep],
                               heights=observed.heights[keep])
            retry = Rejections(max_examples=cfg.max_examples)
            again = _plan_cloud(observed, cfg, retry, attempted, timings)
            if again[0]:  # the plan and its rejections are the retry's; else the first pass says why
                grasps, frame, center, n_slices, summary = again
                rejections = retry
                summary["stray_points_dropped"] = int(stray.sum())
    if not grasps and cfg.complete_round_sections:
        ts = time.perf_counter()
        revolved = _revolve(observed, cfg)
        timings["revolve"] = (time.perf_counter() - ts) * 1e3
        if revolved is not None:  # an upright round object: plan again with its unseen arc filled in
            inp, frame, center, revolved_summary = revolved
            # the plan now stands on the revolved cloud alone (the mirrored faces are not in it)
            summary.update(revolved=revolved_summary, n_inferred=revolved_summary["n_inferred"], completed_axes=[])
            grasps = _plan_variants(inp, frame, center, cfg, rejections, attempted, timings)
    timings["total"] = (time.perf_counter() - t0) * 1e3
    return GraspPlan(grasps=grasps, rejections=rejections, attempted=attempted, object_center=center,
                     center_slices=n_slices, main_axis=frame.main_axis.copy(), timings_ms=timings,
                     completion=summary)


def _plan_cloud(observed: PlanningInput, cfg: GraspPlannerConfig, rejections: Rejections, attempted: list[str],
                timings: dict[str, float]
                ) -> tuple[list[PlannedGrasp], ObjectFrame, np.ndarray, int, dict[str, Any]]:
    """One planning pass over an observed cloud: its box frame, hidden sides mirrored in, the turn centre,
    then the variants. Returns (grasps, frame, centre, centre slices, completion summary)."""
    t0 = time.perf_counter()
    inp = observed
    frame = object_frame(inp.xyz, inp.up)
    completion = complete_hidden_sides(frame, inp.xyz, inp.normals, inp.up, band=cfg.side_face_band,
                                       face_angle_deg=cfg.side_face_angle_deg, hidden_ratio=cfg.hidden_side_ratio,
                                       min_face_points=cfg.min_side_face_points, enabled=cfg.complete_hidden_sides,
                                       spacing=0.25 * cfg.curvature_radius)
    if completion.n_inferred:
        inp = replace(inp, xyz=completion.xyz, normals=completion.normals,
                      heights=completion.xyz @ inp.up + inp.offset, n_observed=completion.n_observed)
        frame = completion.frame(frame)
    rng = np.random.default_rng(cfg.seed)
    # the circle fits see the observed points; along a mirrored axis the object is symmetric about the
    # box's central plane by assumption, so the centre lies on it (an L-shaped section would pull it off)
    center_local, n_slices = estimate_object_center(frame.local[:completion.n_observed], frame.extents,
                                                    cfg.slice_thickness, cfg.center_slices,
                                                    cfg.center_min_points, rng)
    center_local[completion.completed_cols] = 0.0
    center = frame.to_base(center_local[None, :])[0]
    timings["prepare"] = timings.get("prepare", 0.0) + (time.perf_counter() - t0) * 1e3
    for side in completion.incomplete_sides:
        rejections.add("side_not_seen", example={
            "axis": side.axis, "status": side.status, "face_points": list(side.points),
            "why": "an antipodal pair on this axis needs a face at both ends; no scan pose saw one of them"})
    grasps = _plan_variants(inp, frame, center, cfg, rejections, attempted, timings)
    return grasps, frame, center, n_slices, completion.summary()


def _plan_variants(inp: PlanningInput, frame: ObjectFrame, center: np.ndarray, cfg: GraspPlannerConfig,
                   rejections: Rejections, attempted: list[str], timings: dict[str, float]) -> list[PlannedGrasp]:
    """Frontal and/or top-down grasps as ``cfg.mode`` says ('auto': top-down only when frontal found
    nothing); appends the variants run to ``attempted`` (once each) and their times to ``timings``."""
    grasps: list[PlannedGrasp] = []
    if cfg.mode in ("auto", "frontal", "both"):
        ts = time.perf_counter()
        grasps += _plan_frontal(inp, frame, center, cfg, rejections)
        _note(attempted, timings, "frontal", ts)
    if cfg.mode in ("top_down", "both") or (cfg.mode == "auto" and not grasps):
        ts = time.perf_counter()
        grasps += _plan_top_down(inp, frame, center, cfg, rejections)
        _note(attempted, timings, "top_down", ts)
    return grasps


def _note(attempted: list[str], timings: dict[str, float], variant: str, since: float) -> None:
    if variant not in attempted:
        attempted.append(variant)
    timings[variant] = timings.get(variant, 0.0) + (time.perf_counter() - since) * 1e3


def _revolve(observed: PlanningInput, cfg: GraspPlannerConfig
             ) -> tuple[PlanningInput, ObjectFrame, np.ndarray, dict[str, Any]] | None:
    """The observed cloud of an upright round object with its unseen arc filled in about the fitted
    vertical axis (revolve.py), its box frame and its turn centre (the axis at the box's mid-height);
    None when the object is not round about a vertical axis or was seen all round."""
    section = fit_vertical_axis(observed.xyz, observed.normals, observed.up, observed.offset,
                                wall_angle_deg=cfg.side_face_angle_deg, tolerance=cfg.round_section_tolerance,
                                min_seen_arc_deg=cfg.round_min_seen_arc_deg)
    if section is None:
        return None
    rev = revolve_unseen_arc(observed.xyz, observed.normals, observed.up, observed.offset, section,
                             wall_angle_deg=cfg.side_face_angle_deg)
    if not rev.n_inferred:
        return None
    inp = replace(observed, xyz=rev.xyz, normals=rev.normals, heights=rev.xyz @ observed.up + observed.offset,
                  n_observed=rev.n_observed)
    frame = object_frame(inp.xyz, inp.up)
    center = section.axis_point + float((frame.center - section.axis_point) @ inp.up) * inp.up
    return inp, frame, center, rev.summary()


def plan_grasps_for_cloud(cloud: PointCloud, table: Plane, config: GraspPlannerConfig | None = None
                          ) -> GraspPlan:
    """Same as :func:`plan_grasps` for a wire ``PointCloud`` (which must carry normals, frame base)."""
    if cloud.frame != table.frame:
        raise GraspInputError(f"cloud is in {cloud.frame!r} but the table in {table.frame!r}",
                              code="frame_mismatch")
    return plan_grasps(cloud.xyz, cloud.normals, table, config)


# --------------------------------------------------------------------------------------- variants

def _plan_frontal(inp: PlanningInput, frame: ObjectFrame, center: np.ndarray, cfg: GraspPlannerConfig,
                  rej: Rejections) -> list[PlannedGrasp]:
    g = cfg.gripper
    top = _object_top(inp.heights)
    needed = 0.5 * (g.palm_height if cfg.check_palm else g.pad_width) + cfg.table_clearance
    if top < needed:
        rej.add("too_short_for_frontal", example={
            "kind": "frontal", "object_height": top, "needed": needed,
            "why": "a horizontal hand at the object's top would still reach into the table"})
        return []
    table = table_box(inp.xyz, inp.up, inp.offset, cfg.table_box_size, cfg.table_box_height)
    out: list[PlannedGrasp] = []
    slots: dict[tuple[str, str], int] = {}
    for pair, axis, source in _ranked_pairs(inp.xyz, inp.normals, inp.up, frame, cfg, "frontal", rej,
                                            inp.n_observed):
        if slots.get((axis, source), 0) >= cfg.candidates_per_axis:
            continue
        p1, p2 = near_stroke_contacts(inp.xyz, inp.normals, pair.i, pair.j, inp.up, cfg.gripper.max_opening,
                                      cfg.near_stroke_side)
        R, swapped = frontal_rotation(p1, p2, inp.up, np.asarray(cfg.approach_origin, float))
        if _near_stroke_rejected(p1, p2, R, inp.xyz[:inp.n_observed], cfg, rej, "frontal", axis, pair):
            continue
        p_plus, p_minus = (p2, p1) if swapped else (p1, p2)
        mid = 0.5 * (p1 + p2)
        tcp = mid + cfg.grasp_depth * R[:, 0]
        boxes = dict(zip(("pad_plus", "pad_minus"), pad_boxes(R, p_plus, p_minus, cfg), strict=True))
        if cfg.check_palm:
            boxes["palm"] = palm_box(R, tcp, cfg)
        hit = first_overlap(boxes, table, cfg.table_clearance)
        example = {"kind": "frontal", "axis": axis, "rank": pair.rank, "contacts": [p_plus, p_minus]}
        if hit:
            rej.add("collides_with_table", example={**example, "box": hit})
            continue
        n_hit, which = _object_hits(boxes, inp.xyz, cfg)
        if n_hit:
            rej.add("collides_with_object", example={**example, "box": which, "points": n_hit})
            continue
        if _open_pads_hit(p1, p2, R, inp.xyz[:inp.n_observed], cfg, rej, "frontal", axis, pair):
            continue
        nrm = np.array([pair.n_j, pair.n_i] if swapped else [pair.n_i, pair.n_j])
        out.append(_make_grasp("frontal", axis, pair, R, np.array([p_plus, p_minus]), nrm, inp,
                               cfg.grasp_depth, cfg.frontal_offsets_deg, center, cfg, boxes,
                               inp.inferred([pair.i, pair.j])))
        slots[(axis, source)] = slots.get((axis, source), 0) + 1
    out.sort(key=_order)
    return out


def _plan_top_down(inp: PlanningInput, frame: ObjectFrame, center: np.ndarray, cfg: GraspPlannerConfig,
                   rej: Rejections) -> list[PlannedGrasp]:
    top = _object_top(inp.heights)
    crop_bottom = top - cfg.top_down_crop_height
    # contacts closer to the table than twice the clearance cannot be reached by fingertips coming from
    # above (the pad's own tilt and the clearance eat that margin), so they never become candidates
    keep = np.flatnonzero(inp.heights >= max(crop_bottom, 2.0 * cfg.table_clearance))
    if len(keep) < MIN_POINTS:
        rej.add("too_few_points", example={"kind": "top_down", "points_in_crop": len(keep)})
        return []
    xyz, nrm = inp.xyz[keep], inp.normals[keep]
    crop_frame = object_frame(xyz, inp.up)
    below = remainder_box(inp.heights, crop_bottom, inp.up, inp.offset, frame.box)
    table = table_box(inp.xyz, inp.up, inp.offset, cfg.table_box_size, cfg.table_box_height)
    out: list[PlannedGrasp] = []
    n_observed = None if inp.n_observed is None else int(np.count_nonzero(keep < inp.n_observed))
    slots: dict[tuple[str, str], int] = {}
    for pair, axis, source in _ranked_pairs(xyz, nrm, inp.up, crop_frame, cfg, "top_down", rej, n_observed):
        if slots.get((axis, source), 0) >= cfg.candidates_per_axis:
            continue
        p1, p2 = near_stroke_contacts(xyz, nrm, pair.i, pair.j, inp.up, cfg.gripper.max_opening,
                                      cfg.near_stroke_side)
        R, swapped = top_down_rotation(p1, p2, inp.up, np.asarray(cfg.approach_origin, float))
        if _near_stroke_rejected(p1, p2, R, xyz[:n_observed], cfg, rej, "top_down", axis, pair):
            continue
        p_plus, p_minus = (p2, p1) if swapped else (p1, p2)
        # the fingertips stop above the table: lift the pads along the approach until their lowest
        # corner clears it (a no-op unless the contacts are within half a pad length of the table)
        pads = pad_boxes(R, p_plus, p_minus, cfg)
        lowest = min(float((b.corners() @ inp.up).min()) for b in pads) + inp.offset
        rise = cfg.table_clearance + 1e-4 - lowest
        if rise > 0:
            pads = pad_boxes(R, p_plus, p_minus, cfg, back=rise / max(-float(R[:, 0] @ inp.up), 1e-6))
        boxes = dict(zip(("pad_plus", "pad_minus"), pads, strict=True))
        example = {"kind": "top_down", "axis": axis, "rank": pair.rank, "contacts": [p_plus, p_minus]}
        reach = [abs(b.to_local(c[None])[0, 0]) <= b.half_extents[0] for b, c in zip(pads, (p_plus, p_minus),
                                                                                       strict=True)]
        if not all(reach):  # lifted so far that a pad no longer covers its contact
            rej.add("collides_with_table", example={**example, "box": "fingertip", "table": "table"})
            continue
        hit = first_overlap(boxes, below, cfg.table_clearance) if below is not None else None
        if hit:
            rej.add("collides_with_table", example={**example, "box": hit, "table": "object_below_crop"})
            continue
        hit = first_overlap(boxes, table, cfg.table_clearance)
        if hit:
            rej.add("collides_with_table", example={**example, "box": hit, "table": "table"})
            continue
        n_hit, which = _object_hits(boxes, inp.xyz, cfg)
        if n_hit:
            rej.add("collides_with_object", example={**example, "box": which, "points": n_hit})
            continue
        if _open_pads_hit(p1, p2, R, inp.xyz[:inp.n_observed], cfg, rej, "top_down", axis, pair):
            continue
        # the TCP goes where the pads were checked: pushed past the contacts only as far as the pads' lowest
        # corner keeps the clearance, or held back by the rise (a short box: the pushed pads, and the finger
        # links around them, met the table in the arm's check although the pads at the contacts cleared it)
        # (both pads ride level with the TCP along the approach, not each at its own contact: on a scan the
        # two contacts of a 5 cm box were 6 mm apart in height, and the lower pad decides)
        x = R[:, 0]
        mid = 0.5 * (p_plus + p_minus)
        level = pad_boxes(R, p_plus + float((mid - p_plus) @ x) * x, p_minus + float((mid - p_minus) @ x) * x, cfg)
        lowest_level = min(float((b.corners() @ inp.up).min()) for b in level) + inp.offset
        depth = top_down_depth(lowest_level, -float(x @ inp.up), cfg)
        n_pair = np.array([pair.n_j, pair.n_i] if swapped else [pair.n_i, pair.n_j])
        grasp = _make_grasp("top_down", axis, pair, R, np.array([p_plus, p_minus]), n_pair, inp,
                            depth, cfg.top_down_offsets_deg, center, cfg, boxes, inp.inferred(keep[[pair.i, pair.j]]))
        section = round_section(inp.xyz, mid, R[:, 2], inp.up) if cfg.top_down_roll_deg else None
        if section is not None:  # a round body lying across: the grasp may turn about its axis (roll.py)
            grasp.poses.update(roll_poses(grasp.poses, R, section[0], cfg.top_down_roll_deg, inp.up, center,
                                          cfg.turn_deg, np.asarray(cfg.approach_origin, float)))
            grasp.metrics["section_radius"] = section[1]
        elif cfg.top_down_pitch_deg:  # a box: the pitched picks a box thin along the line from the base needs
            grasp.poses.update(pitch_poses(grasp.poses, R, mid, cfg.top_down_pitch_deg, inp.up,
                                           np.asarray(cfg.approach_origin, float),
                                           lambda Rp, m=mid: _open_pads_clear(Rp, m, inp.xyz, cfg)))
        out.append(grasp)
        slots[(axis, source)] = slots.get((axis, source), 0) + 1
    out.sort(key=_order)
    return out


# --------------------------------------------------------------------------------------- helpers

def top_down_depth(lowest: float, descent: float, cfg: GraspPlannerConfig) -> float:
    """How far (m) a top-down TCP goes past the contacts' midpoint along the approach, negative = held back.

    ``lowest``: height above the table of the pads' lowest corner with the pads level with the contacts'
    midpoint; ``descent``: how much of the approach points down (-x . up). At most ``grasp_depth``; never so
    far that that corner comes within ``top_down_tip_clearance`` of the table."""
    room = (lowest - cfg.top_down_tip_clearance) / max(descent, 1e-6)
    return float(min(cfg.grasp_depth, room))


def _ranked_pairs(xyz: np.ndarray, normals: np.ndarray, up: np.ndarray, frame: ObjectFrame,
                  cfg: GraspPlannerConfig, kind: str, rej: Rejections, n_observed: int | None = None
                  ) -> list[tuple[RankedPair, str, str]]:
    """The valid pairs of the y and the z regions as (pair, axis, source), best first per axis and
    source (at most ``max_checks_per_axis`` each); pair-level rejections go to ``rej``.

    Rows from ``n_observed`` on are inferred (mirrored in). The regions are cut from the whole cloud;
    an axis whose regions hold inferred points gives source "completed", and for those axes the regions
    cut from the observed points alone (in the same pass) give source "observed", the pairs an unaided
    GeoGrasp would rank (other axes' pairs are "observed" from the first cut). Each source has
    its own grasp slots, so completing a hidden side adds grasps and never takes away one the observed
    points give.

    Only the region axes that lie along the table are tried: a pair at the two ends of an axis along the
    table normal joins the object's top to its lowest seen points, a vertical line no horizontal or
    downward hand closes on (GeoGrasp likewise takes its initial points along a horizontal axis)."""
    axes = horizontal_axes(frame, up)
    if not axes:
        rej.add("too_few_points", example={"kind": kind, "why": "no box axis along the table"})
        return []
    completed = n_observed is not None and n_observed < len(frame.local)
    # The observed-only cut of a completed axis pairs its hidden end's edge points; their normals lie
    # more than side_face_angle_deg off the axis (that is what made the end hidden), so they can only
    # pass an antipodal test looser than that (the grasp service's): otherwise the cut is skipped.
    observed_cut = completed and cfg.max_contact_angle_deg > cfg.side_face_angle_deg
    regions, n_slice = candidate_regions(frame, cfg.gripper.pad_width, cfg.slice_thickness,
                                         cfg.region_voxel, cfg.curvature_radius,
                                         refit_normals=cfg.refit_normals, axes=axes,
                                         n_observed=n_observed if observed_cut else None,
                                         observed_axes=axes if observed_cut else ())
    if not regions:
        rej.add("too_few_points", example={"kind": kind, "slice_points": n_slice})
        return []
    by_axis: dict[tuple[str, str], list] = {}
    for r in regions:
        by_axis.setdefault((r.axis, r.source), []).append(r)
    out: list[tuple[RankedPair, str, str]] = []
    for (axis, cut), pair_regions in by_axis.items():
        a, b = pair_regions
        inferred = completed and max(a.indices.max(initial=-1), b.indices.max(initial=-1)) >= n_observed
        if cut == "observed" and not by_axis_has_inferred(by_axis, axis, n_observed):
            continue  # the whole-cloud cut of this axis holds no inferred point: it already ranked these
        source = "completed" if inferred else "observed"
        if min(len(a.indices), len(b.indices)) < cfg.min_region_points or a.seed_index == b.seed_index:
            rej.add("too_few_points", example={"kind": kind, "axis": axis, "source": source,
                                               "region_points": [len(a.indices), len(b.indices)]})
            continue
        ranking = rank_region_pair(a, b, xyz, normals, frame.main_axis, up, cfg, cfg.max_checks_per_axis)
        for reason, count in ranking.rejected_counts.items():
            ex = ranking.rejected_best[reason]
            rej.add(reason, count, {"kind": kind, "axis": axis, "source": source, "pairs": count,
                                    "best_contacts": [xyz[ex.i], xyz[ex.j]], **ex.metrics})
        out += [(p, axis, source) for p in ranking.best]
    return out


def by_axis_has_inferred(by_axis: dict[tuple[str, str], list], axis: str, n_observed: int | None) -> bool:
    """Whether the whole-cloud regions of ``axis`` hold an inferred point (row >= ``n_observed``)."""
    regions = by_axis.get((axis, "all"), [])
    return n_observed is not None and any(r.indices.max(initial=-1) >= n_observed for r in regions)


def _order(grasp: PlannedGrasp) -> tuple[float, float]:
    """Grasps on two seen faces first, then by GeoGrasp rank: a mirrored-in contact is an assumption
    (exact for boxes and cans), so it only leads when nothing seen on both sides survives."""
    return grasp.metrics.get("inferred_contacts", 0.0), -grasp.rank


def _object_top(heights: np.ndarray) -> float:
    """Height of the object's top, robust to a few noisy points above it (99.5th percentile)."""
    return float(np.quantile(heights, 0.995))


def _object_hits(boxes: dict[str, OrientedBox], xyz: np.ndarray, cfg: GraspPlannerConfig
                 ) -> tuple[int, str | None]:
    """Object points inside either pad. Pads only: the palm sits behind the fingertips, and the paper's
    0.05 m push assumes the fingers retract as they open, so a palm box would reject grasps that work.
    Both pads share the gripper's rotation, so the cloud is rotated once."""
    pads = [boxes["pad_plus"], boxes["pad_minus"]]
    R = pads[0].rotation
    # cheap prefilter on one coordinate (the pads' common y line), then the full test on the few left
    y = xyz @ R[:, 1]
    for name, pad in zip(("pad_plus", "pad_minus"), pads, strict=True):
        c = pad.center @ R
        near = np.flatnonzero(np.abs(y - c[1]) <= pad.half_extents[1])
        inside = np.all(np.abs(xyz[near] @ R - c) <= pad.half_extents, axis=1)
        n = int(np.count_nonzero(inside))
        if n >= cfg.object_collision_min_points:
            return n, name
    return 0, None


def _near_stroke_rejected(p1: np.ndarray, p2: np.ndarray, R: np.ndarray, xyz: np.ndarray, cfg: GraspPlannerConfig,
                          rej: Rejections, kind: str, axis: str, pair: RankedPair) -> bool:
    """Whether a pair near the stroke (its contacts ``p1``, ``p2`` as ``near_stroke_contacts`` gave them, the hand's
    rotation ``R``) is ``too_wide``, recorded in ``rej``: the object's seen points (``xyz``, not the mirrored-in
    ones, which sit where a guess put them) where the pads close, within
    the pads' length along the approach and their width across it, span more than the stroke along the grasp line.

    Why: the pair's own length is not the object's width between the pads. Two points a little inside a 10.7-10.9
    cm box's faces pass the pair's width test, and so does a pair from an edge across a turned 6.6 x 10.9 cm box
    (10.5 cm long): the pads met the box each time."""
    if not near_stroke(float(pair.metrics["width"]), cfg.gripper.max_opening, cfg.near_stroke_side):
        return False
    mid = 0.5 * (p1 + p2)
    local = (np.asarray(xyz, float) - mid) @ R
    g = cfg.gripper
    # along the approach: the pads' length about where they stand fully open (the grasp's push past the contacts,
    # less the linkage's pull-back at the whole stroke)
    pads_x = cfg.grasp_depth - g.open_retraction
    band = (np.abs(local[:, 0] - pads_x) <= 0.5 * g.pad_length) & (np.abs(local[:, 2]) <= 0.5 * g.pad_width)
    span = float(np.ptp(local[band, 1])) if np.count_nonzero(band) >= 2 else float(np.linalg.norm(p1 - p2))
    if span <= g.max_opening:
        return False
    rej.add("too_wide", example={"kind": kind, "axis": axis, "rank": pair.rank, "contacts": [p1, p2], "width": span,
                                 "why": "the object spans more than the stroke where the pads close"})
    return True


def _open_pads_hit(p1: np.ndarray, p2: np.ndarray, R: np.ndarray, xyz: np.ndarray, cfg: GraspPlannerConfig,
                   rej: Rejections, kind: str, axis: str, pair: RankedPair) -> bool:
    """Whether the pads of the hand with rotation ``R``, opened the whole stroke about the contacts' middle, meet
    the object's seen points (``xyz``), recorded in ``rej`` as ``too_wide``: nothing the gripper opens to gets
    them round it. A pair's own length is not the object's width along its line: on a 9.9 x 14.3 cm box a 9.4 cm
    pair, one contact mirrored in where the view did not reach, had the seen box 2-4 mm past where its fully open
    pads stand, and every pick of it met the box with a pad (three in a whole MuJoCo run).

    A pair on an edge (a contact normal more than 30 degrees off the line, ``near_stroke.square_to_faces``) is
    not tested: closing on the edge turns the box in the hand until its faces lie on the pads, and the open pads'
    reach past the seen corner is that turn (a 9.96 cm edge pair on a 6.9 x 9.3 cm box was held and turned in
    MuJoCo runs; on views of that box such edge pairs' open pads stand 7-8 mm inside the seen corner)."""
    if not square_to_faces(np.array([pair.n_i, pair.n_j]), 0, 1, p1 - p2) or \
            _open_pads_clear(R, 0.5 * (p1 + p2), xyz, cfg):
        return False
    rej.add("too_wide", example={"kind": kind, "axis": axis, "rank": pair.rank, "contacts": [p1, p2],
                                 "why": "the fully open pads meet the object"})
    return True


def _open_pads_clear(R: np.ndarray, mid: np.ndarray, xyz: np.ndarray, cfg: GraspPlannerConfig) -> bool:
    """Whether the pads of a gripper with rotation ``R``, fully open about ``mid``, stay clear of the object
    points, at the contacts' level and where the linkage pulls them back as they open
    (``GripperConfig.open_retraction``): a hand coming in tilted against a box's faces meets them there."""
    g = cfg.gripper
    y, x = R[:, 1], R[:, 0]
    reach = 0.5 * (g.max_opening - cfg.pad_gap)  # pad_boxes puts each pad's inner face pad_gap/2 past its contact
    for back in (0.0, g.open_retraction):
        pads = pad_boxes(R, mid + reach * y - back * x, mid - reach * y - back * x, cfg)
        if _object_hits(dict(zip(("pad_plus", "pad_minus"), pads, strict=True)), xyz, cfg)[0]:
            return False
    return True


def _make_grasp(kind: str, axis: str, pair: RankedPair, R: np.ndarray, contacts: np.ndarray,
                contact_normals: np.ndarray, inp: PlanningInput, depth: float, offsets: tuple[float, ...],
                center: np.ndarray, cfg: GraspPlannerConfig, boxes: dict[str, OrientedBox], inferred: int
                ) -> PlannedGrasp:
    """A surviving grasp with its poses; ``contacts`` = (p_plus, p_minus), y running minus → plus;
    ``inferred`` = how many of the two contacts lie on a mirrored-in face (metric ``inferred_contacts``)."""
    mid = 0.5 * (contacts[0] + contacts[1])
    poses = grasp_poses(R, mid, depth, cfg.pregrasp_back_off, offsets, inp.up, center, cfg.turn_deg)
    metrics = {**pair.metrics, "depth": depth, "contact_height": float(mid @ inp.up + inp.offset),
               "inferred_contacts": float(inferred)}
    return PlannedGrasp(kind=kind, axis=axis, contacts=np.asarray(contacts, float),
                        contact_normals=np.asarray(contact_normals, float), width=pair.metrics["width"],
                        rank=pair.rank, metrics=metrics, poses=poses, collision_boxes=boxes)

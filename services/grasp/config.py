"""Configuration of the grasp planner: the gripper's geometry and the planner's knobs.

Everything the planner knows about the hand comes from :class:`GripperConfig`, so another parallel
gripper is a config change, not a code change. Defaults describe the ROBOTIS RH-P12-RN(A) on the PAPRAS
arm; where a figure comes from is written next to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from common.stroke import NEAR_STROKE_SIDE, STROKE
from services.grasp.errors import GraspConfigError


@dataclass(frozen=True)
class GripperConfig:
    """Geometry of a parallel-jaw gripper, in metres.

    Gripper frame (docs/conventions.md): x = approach, y = across the fingers (closing direction),
    z = up when approaching horizontally.

    Defaults: ROBOTIS RH-P12-RN(A).
    - ``max_opening`` 0.106 m: ROBOTIS e-manual, RH-P12-RN(A) hardware revision 1 (since 2019-11-04),
      stroke 0-106 mm (revision 0 had 0-109 mm; 0.106 is the conservative one).
    - ``finger_length`` 0.086 m: the paper's measured finger length when fully extended (section II-B).
    - pad and palm sizes: bounding boxes of the RH-P12-RN meshes shipped with the PAPRAS description
      (``rh_p12_rn_l2.stl``: distal link 26 mm wide, reaching 40 mm past its joint, 22 mm thick;
      ``rh_p12_rn_base.stl``: palm 54 x 80 x 59 mm).
    """

    name: str = "RH-P12-RN(A)"
    max_opening: float = STROKE
    min_opening: float = 0.0
    finger_length: float = 0.086
    pad_width: float = 0.026
    """Size of a pad along the gripper's z (across the finger); also the 'fingertip width' of GeoGrasp."""
    pad_length: float = 0.040
    """Size of a pad along the approach (gripper x)."""
    pad_thickness: float = 0.022
    """Size of a pad along the closing direction (gripper y)."""
    palm_height: float = 0.054
    """Palm size along the gripper's z: the palm passes at contact height, so it decides how low a
    frontal grasp can go before the hand hits the table."""
    palm_width: float = 0.080
    palm_depth: float = 0.059
    open_retraction: float = 0.0273
    """How far the parallel linkage pulls the pads back along the approach when fully open (measured on the
    URDF linkage with pinocchio; the twin's ``services/sim/gripper.GripperSpec.retraction`` at 0.106 m)."""

    def __post_init__(self) -> None:
        _check_positive(self, exclude=("name", "min_opening"))
        if not 0.0 <= self.min_opening < self.max_opening:
            raise GraspConfigError("gripper min_opening must be in [0, max_opening)",
                                   detail={"min_opening": self.min_opening, "max_opening": self.max_opening})

    @property
    def pad_extents(self) -> tuple[float, float, float]:
        """Full pad box size along the gripper's (x, y, z)."""
        return (self.pad_length, self.pad_thickness, self.pad_width)

    @property
    def palm_extents(self) -> tuple[float, float, float]:
        return (self.palm_depth, self.palm_width, self.palm_height)


@dataclass(frozen=True)
class GraspPlannerConfig:
    """Knobs of the GeoGrasp-style planner (Zapata-Impata et al. 2019, as modified in the paper II-B).

    The ranking constants are the authors' ("BEST VALUES FOR W1 AND W2"): rank = 1.5·r1 + 1.0·r2 with
    r1 = 2 − d̂1 − d̂2 − 10·(cosβ − 0.2) and r2 = 2 − ĉ1 − ĉ2 + 2·min(cosα1, cosα2); pairs with r1 < 1 or
    r2 < 1 are dropped.
    """

    gripper: GripperConfig = field(default_factory=GripperConfig)

    mode: str = "auto"
    """'auto': frontal, then top-down only when frontal yields nothing; 'frontal'; 'top_down'; 'both'."""

    # --- candidates
    slice_thickness: float = 0.007
    """Thickness of the central slice (GeoGrasp kGraspPlaneApprox = 7 mm)."""
    region_voxel: float = 0.003
    """Candidate regions are thinned to one point per voxel of this size; bounds the pair count
    (GeoGrasp voxelises its regions far more coarsely, at gripTip/2 = 12.5-15 mm)."""
    curvature_radius: float = 0.01
    """Neighbourhood radius of the surface-variation curvature of candidate points."""
    refit_normals: bool = True
    """Rank with normals re-estimated from each candidate's 1 cm neighbourhood (the same PCA that gives
    its curvature, as GeoGrasp does with PCL's NormalEstimation) rather than the input normals: dense
    scans estimated with a small neighbourhood carry normals too noisy for the antipodal test."""
    min_region_points: int = 3
    complete_hidden_sides: bool = True
    """Mirror a side face the scan poses could not see onto its end of the box (completion.py): a box
    turned away from the cameras shows no two opposite side faces, and without it no antipodal pair
    exists. False: plan on observed points only (the plan then reports ``side_not_seen``)."""
    side_face_band: float = 0.004
    """Minimum depth, from a box side, of the band whose axis-facing points count as that side's face
    (a quarter of the half extent when larger)."""
    side_face_angle_deg: float = 30.0
    """A point belongs to a side face when its normal is within this angle of the box axis."""
    hidden_side_ratio: float = 0.05
    """An end of an axis is hidden when it has at most this fraction of the other end's face points."""
    min_side_face_points: int = 20
    """The seen end needs at least this many face points to be mirrored."""
    drop_stray_points: bool = True
    """When the cloud gives no grasp and holds stray returns (a point with no neighbours at the cloud's own
    spacing, stray.py), drop them and plan again: one flying pixel beyond a face moves the box frame's end
    and hides that face from the completion. False: the plan stays empty."""
    complete_round_sections: bool = True
    """When the cloud (mirror completion included) gives no grasp and the object stands round on a vertical
    axis (a can, a jar, a bottle), fill the arc of wall no scan pose saw by turning the seen wall about that
    axis and plan again (revolve.py). False: the plan stays empty."""
    round_section_tolerance: float = 0.002
    """A height band of wall is round when its circle fit's RMS residual is within this (m), and the bands'
    centres must lie within it of one vertical axis."""
    round_min_seen_arc_deg: float = 120.0
    """The seen wall must span this much azimuth about the axis for the fit to be trusted."""
    candidates_per_axis: int = 1
    """Grasps kept per region axis (the paper: the best one)."""
    max_checks_per_axis: int = 25
    """How far down an axis's ranking the collision filter goes looking for a collision-free pair: the
    paper checks only the best pair, which loses e.g. a lying can whose best pair is tilted so the palm
    grazes the table while the next pair is level."""

    # --- ranking
    w1: float = 1.5
    w2: float = 1.0
    r1_min: float = 1.0
    r2_min: float = 1.0
    cos_beta_gain: float = 10.0
    cos_beta_offset: float = 0.2
    max_grasp_line_tilt_deg: float = 15.0
    """A grasp line steeper than this against the table plane cannot be held by a horizontal
    (frontal) or vertical (top-down) approach: rejected as ``grasp_line_not_horizontal``."""

    near_stroke_side: float = NEAR_STROKE_SIDE
    """m a side the fully open pads clear a grasp's width under which the grasp is near the stroke
    (``common.stroke``): its contacts are then settled on their faces and levelled (``near_stroke.py``). There the
    pads fit beside the object only square to its faces. Other grasps keep the line through their two contacts."""

    max_contact_angle_deg: float = 20.0
    """Both contact normals must lie within this angle of the grasp line (``not_antipodal``). Not in
    GeoGrasp: its r2 >= 1 test lets a pair with cosα = 0 through whenever both points have the region's
    lowest curvature (min-max normalisation makes that 0), e.g. two points on one flat face."""

    # --- collisions
    table_box_size: float = 0.5
    table_box_height: float = 0.025
    pad_gap: float = 0.02
    """The paper's g: each pad box centre sits g/2 beyond its contact along the grasp line (padding
    for motion errors)."""
    table_clearance: float = 0.005
    """Minimum gap kept between the hand and the table."""
    top_down_tip_clearance: float = 0.008
    """Gap kept below a top-down TCP's pads (at the TCP's level) when choosing how deep it goes: the
    RH-P12-RN's finger links closed to ~2 cm reach 3 mm past the pad box (the arm's collision meshes: a
    straight-down TCP clears the table from 23 mm up, the pad box from 20 mm), and a registered table plane
    was 2.7 mm below the arm's table (cream cheese standing on edge, a 12-view physics scan)."""
    check_palm: bool = True
    """Also test a palm box against the table for frontal grasps (the paper tests the pads only)."""
    object_collision_min_points: int = 3
    """A pad collides with the object when at least this many object points lie inside it (a single
    stray point is sensor noise)."""

    # --- poses
    grasp_depth: float = 0.05
    """The paper's 0.05 m push of the TCP past the contact midpoint along the approach."""
    pregrasp_distance: float | None = None
    """Back-off of the pre-grasps along the approach; None = the gripper's finger length (0.086 m)."""
    frontal_offsets_deg: tuple[float, ...] = (15.0,)
    top_down_offsets_deg: tuple[float, ...] = (15.0, 30.0, 45.0)
    top_down_roll_deg: tuple[float, ...] = (30.0, 45.0)
    """Top-down grasps on a round section also turned about the lying axis by these angles (``roll.py``)."""
    top_down_pitch_deg: tuple[float, ...] = (35.0, 40.0)
    """Top-down grasps on anything else also pitched along a grasp line that runs along the line from the
    base, the approach leaning away from the base by these angles (``pitch.py``): at 0.60 m the arm reaches
    a 35-40 degree lean (30 was out of reach above a 15 cm box), and the open pads, tilted against a box's
    faces, clear a 5.4 cm box at 35 degrees with 5 mm to spare, at 40 degrees with 0.5 mm."""
    turn_deg: float = 30.0
    """Turn of the object about the table normal; positive = right-handed about the upward normal
    (counter-clockwise seen from above). The paper turns clockwise: use -30 for that."""
    approach_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Frontal grasps approach from this side (the arm's base), so the hand never reaches around."""

    # --- centre estimate
    center_slices: int = 10
    center_min_points: int = 12
    seed: int = 0

    # --- top-down
    top_down_crop: float | None = None
    """Height of the top crop for top-down grasps; None = the finger length (0.086 m)."""

    max_examples: int = 3
    """Rejection examples kept per reason."""

    def __post_init__(self) -> None:
        _check_positive(self, exclude=("gripper", "mode", "pregrasp_distance", "frontal_offsets_deg",
                                       "top_down_offsets_deg", "top_down_roll_deg", "top_down_pitch_deg", "turn_deg",
                                       "approach_origin",
                                       "seed",
                                       "top_down_crop", "cos_beta_offset", "r1_min", "r2_min",
                                       "check_palm", "w1", "w2", "table_clearance", "max_examples"))
        if self.mode not in ("auto", "frontal", "top_down", "both"):
            raise GraspConfigError(f"unknown planner mode {self.mode!r}",
                                   detail={"allowed": ["auto", "frontal", "top_down", "both"]})
        for name in ("max_grasp_line_tilt_deg", "max_contact_angle_deg", "side_face_angle_deg"):
            if not 0.0 < getattr(self, name) <= 90.0:
                raise GraspConfigError(f"{name} must be in (0, 90]", detail={name: getattr(self, name)})
        for name in ("pregrasp_distance", "top_down_crop"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise GraspConfigError(f"{name} must be positive or None", detail={name: value})
        if not 0.0 < self.round_min_seen_arc_deg < 360.0:
            raise GraspConfigError("round_min_seen_arc_deg must be in (0, 360)",
                                   detail={"value": self.round_min_seen_arc_deg})
        if not 0.0 < self.hidden_side_ratio < 1.0:
            raise GraspConfigError("hidden_side_ratio must be in (0, 1)", detail={"value": self.hidden_side_ratio})
        if self.table_clearance < 0:
            raise GraspConfigError("table_clearance must be >= 0")

    @property
    def pregrasp_back_off(self) -> float:
        return self.gripper.finger_length if self.pregrasp_distance is None else self.pregrasp_distance

    @property
    def top_down_crop_height(self) -> float:
        return self.gripper.finger_length if self.top_down_crop is None else self.top_down_crop


def _check_positive(cfg: object, exclude: tuple[str, ...]) -> None:
    """Reject non-finite numbers, and non-positive ones outside ``exclude``: a zero pad or slice would
    silently find nothing."""
    for f in fields(cfg):  # type: ignore[arg-type]
        value = getattr(cfg, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if not math.isfinite(value):
            raise GraspConfigError(f"{type(cfg).__name__}.{f.name} must be finite", detail={f.name: value})
        if f.name not in exclude and value <= 0:
            raise GraspConfigError(f"{type(cfg).__name__}.{f.name} must be a positive number",
                                   detail={f.name: value})

"""Configuration of static registration: one dataclass, two profiles.

``StaticConfig()`` is the ``default`` profile (arm poses as the prior, region of interest, verify, global
fallback); ``StaticConfig.paper()`` reproduces section II-A of the paper step by step. Every number has a
default that works for a D435 at 0.3-0.6 m from a grocery-sized object; override any by keyword.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any, Literal

from common.pose_accuracy import CONSERVATIVE, PoseAccuracy

Profile = Literal["default", "paper"]
OdometryBackend = Literal["legacy", "tensor"]
ODOMETRY_BACKENDS: tuple[str, ...] = ("legacy", "tensor")


@dataclass(frozen=True)
class StaticConfig:
    profile: Profile = "default"
    seed: int = 0  # seeds every RANSAC (Open3D's global random generator), so runs are reproducible

    # --- back-projection -------------------------------------------------------------------------------
    depth_min: float = 0.1  # m; the D435 returns nothing useful closer
    depth_max: float = 1.2  # m; the workspace is within reach of the arm, farther is background
    edge_threshold: float | None = 0.01  # m; drop pixels at depth jumps (silhouettes, flying pixels)

    # --- region of interest (default profile) -----------------------------------------------------------
    # Cylinder about the table normal (or a sphere when no up direction is known) around the seed point:
    # the first scan's centre-pixel depth. Cutting early is most of the speed-up over the paper.
    roi_radius: float | None = 0.2  # m; None disables the crop
    roi_below: float = 0.03  # m kept below the table top (height 0 along expected_up in base)
    roi_above: float = 0.35  # m kept above the table top
    centre_window: int = 15  # px; the centre depth is the median valid depth in this window

    # --- local registration from the arm's poses (default profile) --------------------------------------
    # 1st choice: dense RGB-D odometry (photometric + depth) seeded with the arm's relative pose
    # full resolution with one iteration at the finest level: worst pose error over 9 twin views 0.20 mm
    # (0.97 mm at half resolution, 2 levels), for ~0.35 CPU-s more per view
    odometry_step: int = 1  # image decimation (2: 320x240 from 640x480)
    # (16, 16, 1), was (8, 4, 1): with the `realistic` twin's 1-3 mm / 0.3-1 deg per-scan error the odometry
    # had not converged along the weakly constrained direction (camera slide vs tilt) after 8 + 4 coarse
    # iterations: 9 of 48 realistic scan pairs > 1 mm (worst 25.9 mm), 3 of 48 (worst 8.0 mm) with 16 + 16,
    # for ~0.12 CPU-s more per pair (the coarse levels are cheap; the full-resolution level stays at one)
    odometry_iterations: tuple[int, ...] = (16, 16, 1)  # per pyramid level, coarse to fine
    # Reverse seed pass: before the forward odometry (scan j onto scan 0), the reverse one (scan 0
    # onto scan j) from the inverted prior, on images decimated by a further ``odometry_seed_step``; its
    # inverse seeds the forward run. From a prior several mm off the forward run can stall in a nearby
    # minimum while the reverse one, whose correspondences come from the other image, does not: realistic
    # milk/soup/sauce pairs with the forward run alone 3 of 12 milk pairs > 1 mm (worst 8.0 mm), reseeded
    # 0 of 12 (worst 0.57 mm), for ~0.18 CPU-s more per pair. None: no seed pass (the arm's prior seeds).
    odometry_seed_iterations: tuple[int, ...] | None = (16, 16)  # per pyramid level of the seed pass
    odometry_seed_step: int = 2  # the seed pass's images are this much coarser than the forward run's
    odometry_hybrid: bool = True  # photometric + depth terms (False: photometric only)
    odometry_max_depth_diff: float = 0.02  # m; pixel pairs farther apart in depth are not matched
    # Which implementation runs both odometry passes: "tensor" (o3d.t.pipelines.odometry on images and a pyramid
    # prepared as the legacy prepares them, one level per call: tensor_odometry.py) or "legacy"
    # (o3d.pipelines.odometry). The same objective: over `bench reconstruct`'s 7 objects every object's worst scan
    # error within 0.05 mm of the legacy's, for 0.22-0.28 CPU-s a scan pair against 0.58-0.75. The tensor one with
    # Open3D's own defaults (7 cm outlier truncation, 1:1 photometric/depth weights, Huber, no blur, its own
    # pyramid) is a different objective and let box, cup and bottle pairs slide by 5-20 mm (docs).
    odometry_backend: OdometryBackend = "tensor"
    # Cut both odometry passes' images to one rectangle: the union of the view's ROI pixel bounding boxes grown
    # by this margin (px), snapped to the coarsest pyramid level (odometry_window.py); without a region of
    # interest the whole image. None (the default): the whole image. Measured over `bench reconstruct`'s 7
    # objects, margin 16: 14-33 % less odometry CPU, but the table outside the rectangle is part of what pins the
    # slide: cylinder and cup slid 32 mm, tomato_sauce 6.2 mm, every object's worst error grew (docs).
    odometry_window_margin: int | None = None
    # 2nd choice (odometry failed the check): coarse-to-fine GICP from the arm's pose on the ROI clouds
    local_voxels: tuple[float, ...] = (0.005, 0.002)
    local_corr_factor: float = 3.0  # max correspondence distance = factor x voxel
    local_iterations: int = 40
    color_lambda_geometric: float = 0.968  # colored ICP weight of geometry vs color (paper profile)

    # 3rd step of a local result (odometry or GICP passed the check): object refinement. The scan's table
    # dominates the odometry and the check, and a plane lets the camera slide: on a realistic milk acquisition
    # one odometry result stalled 1.5 deg / 9.3 mm (at the object) off, yet scored higher on the check than
    # the true pose (0.874 vs 0.848), and its view opened the 12-view loop to 9.3 mm. On the table-free
    # clouds at ``object_voxel`` the same pair reads 0.736 vs 0.864, and point-to-plane ICP on them from the
    # odometry result reaches 0.18 mm. The refined pose replaces the local one only when it raises that
    # object fitness by ``object_min_gain`` (a right pose cannot gain that much: it leaves the good ones be).
    object_refine: bool = True
    object_voxel: float = 0.002  # m; the table-free clouds the refinement runs and is scored on
    object_corr: tuple[float, ...] = (0.008, 0.003)  # m; point-to-plane passes, coarse to fine
    object_iterations: int = 20  # per pass (~20 ms a pass on a milk carton's ~6000 points)
    object_score_corr: float = 0.002  # m; correspondence distance of the object fitness
    object_min_gain: float = 0.02  # object fitness the refinement must add to be kept
    object_min_points: int = 300  # table-free points (at object_voxel) below which there is nothing to refine on
    # the refinement fixes stalls of ~1.5 deg / ~9 mm; a bigger step is ICP sliding along what geometry alone
    # cannot see (a can turning about its axis: 5 deg / 28 mm on a realistic tomato_sauce pair, with the object
    # fitness rising) and is not kept, however wide the arm's plausible window
    object_max_step_m: float = 0.015
    object_max_step_deg: float = 2.0

    # --- verification: when is a result trusted ----------------------------------------------------------
    check_voxel: float = 0.003  # m; the clouds a result is checked on
    check_corr_factor: float = 2.0  # correspondence distance of the check = factor x check_voxel
    min_fitness: float = 0.3  # fraction of source points with a correspondence
    max_rmse: float = 0.003  # m, inlier RMSE

    # --- plausibility: what the arm's accuracy can explain (plausibility.py) -----------------------------
    # The arm's camera pose accuracy (one sigma per camera pose: position error size in mm, orientation error
    # angle in deg), from the robot configuration (``pose_accuracy``) or the session; the default is
    # ``common.pose_accuracy.CONSERVATIVE``, for sessions that state none. A correction of the arm's relative
    # pose beyond ``plausible_sigmas`` of what two such poses allow (the orientation error also swings the
    # baseline between the scans) is rejected however well it fits, and the fallback search never leaves
    # that window. The floors keep a perfect arm (sigma 0) from rejecting the registration's own noise.
    arm_position_sigma_mm: float = CONSERVATIVE.position_sigma_mm
    arm_orientation_sigma_deg: float = CONSERVATIVE.orientation_sigma_deg
    plausible_sigmas: float = 5.0
    plausible_floor_mm: float = 5.0
    plausible_floor_deg: float = 1.0

    # --- global registration (paper) and the default's fallback search ----------------------------------
    global_voxel: float = 0.01  # m; FPFH features at this voxel (radius 5 x voxel)
    global_object_voxel: float = 0.005  # m; the default's fallback matches the table-free object, finer
    # The default's fallback (window_search.py) starts ICP on the table-free clouds from a fixed grid inside
    # the plausible window: yaw about the table normal at these fractions of the rotation bound, tilt about
    # the two horizontal axes at +-``search_tilt_fraction``, each with the prior's shift and with the shift
    # that lines up the two objects' centroids (clipped to the window). Deterministic: no random draw.
    search_yaw_fractions: tuple[float, ...] = (0.0, -0.5, 0.5, -1.0, 1.0)
    search_tilt_fraction: float = 0.5
    search_corr: tuple[float, ...] = (0.015, 0.008)  # m; point-to-plane passes of each start, coarse to fine
    search_iterations: int = 15  # per pass
    search_refine_top: int = 2  # best candidates (object fitness) given the full refinement and check
    ransac_iterations: int = 100000
    ransac_confidence: float = 0.999
    fpfh_radius_factor: float = 5.0
    ransac_corr_factor: float = 1.5

    # --- paper pipeline (II-A) ---------------------------------------------------------------------------
    paper_refine_voxels: tuple[float, ...] = (0.005, 0.002)  # color ICP then GICP at each
    paper_final_voxel: float = 0.001  # point-to-plane after removing non-overlapping points

    # --- pose graph of the 3 scans ----------------------------------------------------------------------
    # The paper registers every pair into a pose graph. In the default profile each scan registers to scan
    # 0 directly: the 2->1 pair has the widest baseline and least overlap, and pulling the graph toward it
    # made poses worse (mean 0.43 vs 0.29 mm over 10 twin views), at one more pair's cost.
    use_pose_graph: bool = False

    # --- fusion and isolation ----------------------------------------------------------------------------
    output_voxel: float = 0.002  # m; voxel of PC_global and of the object cloud
    plane_distance: float = 0.004  # m; RANSAC inlier distance of the table plane
    plane_iterations: int = 500
    plane_voxel: float = 0.005  # m; the plane is searched on a cloud this coarse (speed), then refit
    # The table is chosen among table_planes planes by the prior, not by size: a wall behind the object is
    # often the biggest plane, and a camera looking across the table sees only a grazing strip of it.
    table_planes: int = 6  # planes searched, largest first (1: the paper's "dominant plane")
    min_table_fraction: float = 0.03  # of the cloud's points must lie on the table plane
    min_table_points: int = 200
    expected_up: tuple[float, float, float] | None = (0.0, 0.0, 1.0)  # table normal in base; None: unknown
    max_table_tilt_deg: float = 25.0
    expected_table_height: float | None = 0.0  # m along expected_up (base: table top at 0); None: anywhere
    table_height_tolerance: float = 0.08  # m; a plane farther from the expected height is not the table
    table_clearance: float = 0.004  # m; points closer than this to the table are table
    max_object_height: float = 0.4  # m; above this, points are not on-table objects
    cluster_voxel: float = 0.004  # m; DBSCAN runs on this coarser copy, labels go back by nearest point
    dbscan_eps: float = 0.012  # m
    dbscan_min_points: int = 8
    max_support_gap: float | None = 0.02  # m; a cluster whose lowest point is higher does not stand on the table
    min_object_points: int = 30  # points of a cluster at cluster_voxel to count as an object
    select_by: Literal["nearest_point", "centroid"] = "nearest_point"

    @classmethod
    def paper(cls, **overrides: Any) -> StaticConfig:
        """The paper's profile: no pose prior, no crop, global registration first, 1 mm final voxel."""
        base = dict(profile="paper", roi_radius=None, output_voxel=0.002, select_by="centroid", use_pose_graph=True)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def for_profile(cls, profile: str, **overrides: Any) -> StaticConfig:
        if profile == "paper":
            return cls.paper(**overrides)
        if profile == "default":
            return cls(**overrides)
        raise ValueError(f"unknown static profile {profile!r} (expected 'default' or 'paper')")

    def __post_init__(self) -> None:
        if self.table_planes < 1:
            raise ValueError(f"table_planes must be at least 1, got {self.table_planes}")
        if not 0.0 <= self.min_table_fraction <= 1.0:
            raise ValueError(f"min_table_fraction must be in [0, 1], got {self.min_table_fraction}")
        if self.odometry_seed_step < 1:
            raise ValueError(f"odometry_seed_step must be at least 1, got {self.odometry_seed_step}")
        if self.odometry_backend not in ODOMETRY_BACKENDS:
            raise ValueError(f"odometry_backend must be one of {', '.join(ODOMETRY_BACKENDS)}, "
                             f"got {self.odometry_backend!r}")
        if self.odometry_window_margin is not None and self.odometry_window_margin < 0:
            raise ValueError(f"odometry_window_margin must be non-negative or None, got {self.odometry_window_margin}")
        if self.odometry_seed_iterations is not None and not self.odometry_seed_iterations:
            raise ValueError("odometry_seed_iterations must name at least one pyramid level (or be None)")
        if self.object_voxel <= 0 or self.object_score_corr <= 0 or not self.object_corr:
            raise ValueError("object_voxel and object_score_corr must be positive and object_corr non-empty")
        self.accuracy  # noqa: B018 - validates the two sigmas (a typed error names the key)
        if not self.plausible_sigmas > 0 or self.plausible_floor_mm < 0 or self.plausible_floor_deg < 0:
            raise ValueError("plausible_sigmas must be positive and the plausibility floors non-negative")
        if not self.search_corr or self.search_refine_top < 1:
            raise ValueError("search_corr must name at least one pass and search_refine_top be at least 1")
        if self.table_height_tolerance <= 0:
            raise ValueError(f"table_height_tolerance must be positive, got {self.table_height_tolerance}")

    def with_accuracy(self, accuracy: PoseAccuracy | None) -> StaticConfig:
        """This config with the arm's stated pose accuracy (None: unchanged)."""
        if accuracy is None:
            return self
        return replace(self, arm_position_sigma_mm=float(accuracy.position_sigma_mm),
                       arm_orientation_sigma_deg=float(accuracy.orientation_sigma_deg))

    @property
    def accuracy(self) -> PoseAccuracy:
        return PoseAccuracy(self.arm_position_sigma_mm, self.arm_orientation_sigma_deg)

    def with_(self, **changes: Any) -> StaticConfig:
        return replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

"""Pre-processing of the 12 views (paper II-C-1): pre-rotate, stack, quantise colors, regions.

Each view is rotated back by its commanded cumulative turn about the table normal through its own
estimated centre and then moved so its centre lands on view 0's centre. After this every view sits
roughly where view 0 is, off only by the turn error and the centre estimate's error, which is what the
pair registration then corrects. Only the in-plane part of the centre offset is used for stacking: the
object stands on the same table in every view, so a height difference between two centre estimates is
estimation noise, not motion.

Colors are quantised by one k-means palette fitted on all views together (scikit-learn), so that a
color means the same thing in every view: the paper found color ICP does better with fewer colors.

With ``regions`` on, each view is split into regions (``good.segment_regions``) and the three most
similar region pairs between neighbours are found with GOOD at n = 10, 30, 50 (``good.top_region_pairs``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from sklearn.cluster import KMeans

from common.geometry import make_transform, rotation_about_line
from services.registration.cloud import from_o3d, to_o3d
from services.registration.dynamic.views import DynamicRegistrationError, DynamicView, validate_views


@dataclass(frozen=True)
class PreprocessConfig:
    """Knobs of the pre-processing; defaults follow the paper where it gives numbers."""

    color_clusters: int = 8  # n of the color quantiser (the paper does not give its value)
    kmeans_samples: int = 30_000  # points (over all views) the palette is fitted on
    normal_radius: float = 0.005  # for views that come without normals
    region_voxel: float = 0.003  # regions and GOOD work on a 3 mm copy: fast, and GOOD is coarse anyway
    n_regions: int = 6
    good_bins: tuple[int, ...] = (10, 30, 50)
    region_pairs: int = 3
    seed: int = 0
    # 0: the palette is fitted on every view (one color meaning for the whole scan). n > 0: on the first n
    # views only, so pair jobs can be built while later views are still being captured (the incremental
    # model, docs/dynamic-registration.md): a job's inputs then never change once its two views exist.
    palette_views: int = 0

    def __post_init__(self) -> None:
        if self.palette_views < 0:
            raise DynamicRegistrationError("palette_views must be >= 0 (0 = all views)", code="bad_value",
                                           detail={"palette_views": self.palette_views})


@dataclass
class Cloud:
    """Picklable colored cloud with normals (float32 xyz/normals, uint8 rgb)."""

    xyz: np.ndarray
    rgb: np.ndarray
    normals: np.ndarray

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def subset(self, idx: np.ndarray) -> Cloud:
        return Cloud(self.xyz[idx], self.rgb[idx], self.normals[idx])

    def transformed(self, T: np.ndarray) -> Cloud:
        xyz = (self.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
        nrm = (self.normals.astype(np.float64) @ T[:3, :3].T).astype(np.float32)
        return Cloud(xyz, self.rgb, nrm)

    def to_o3d(self) -> o3d.geometry.PointCloud:
        return to_o3d(self.xyz, self.rgb, self.normals)

    @classmethod
    def from_o3d(cls, pcd: o3d.geometry.PointCloud) -> Cloud:
        """``cloud.from_o3d``'s arrays, normals made unit length (zero where there are none)."""
        wire = from_o3d(pcd)
        n = len(wire.xyz)
        nrm = np.asarray(pcd.normals) if pcd.has_normals() else np.zeros((n, 3))  # unit length in float64 first
        norm = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.where(norm > 1e-9, nrm / np.maximum(norm, 1e-9), nrm)
        rgb = wire.rgb if wire.rgb is not None else np.zeros((n, 3), np.uint8)
        return cls(wire.xyz, rgb, nrm.astype(np.float32))

    def downsampled(self, voxel: float) -> Cloud:
        return Cloud.from_o3d(self.to_o3d().voxel_down_sample(voxel)) if voxel > 0 else self


@dataclass
class PreparedView:
    """A view after pre-processing, in the stacked frame (≈ view 0's ``base``).

    ``T_stack_view`` maps the view's own ``base`` points into the stacked frame; ``cloud`` carries the
    original colors, ``reduced`` the quantised ones (same points). ``regions`` are clouds of the 3 mm copy.
    """

    index: int
    T_stack_view: np.ndarray
    cloud: Cloud
    reduced: Cloud
    regions: list[Cloud] = field(default_factory=list)


@dataclass
class Prepared:
    """All views pre-processed, plus the stacking centre and the turn axis (table normal)."""

    views: list[PreparedView]
    center: np.ndarray
    axis: np.ndarray
    region_pairs: dict[tuple[int, int], list[tuple[int, int]]]
    palette: np.ndarray
    seconds: float = 0.0


def prerotation(view: DynamicView, ref_center: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """T mapping the view's ``base`` into the stacked frame: undo the commanded turn, then stack centres."""
    c = np.asarray(view.center, dtype=float)
    R_undo = rotation_about_line(axis, c, -np.radians(view.commanded_turn_deg))
    shift = np.asarray(ref_center, dtype=float) - c
    shift -= np.dot(shift, axis) * axis  # in-plane only: the object stands on the same table
    return make_transform(None, shift) @ R_undo


def fit_palette(rgbs: list[np.ndarray], n: int, samples: int, seed: int) -> np.ndarray:
    """k-means color palette (n, 3) float fitted on a random sample of all views' colors."""
    allrgb = np.vstack(rgbs).astype(np.float32)
    if n < 1:
        raise DynamicRegistrationError("color_clusters must be >= 1", code="bad_value")
    rng = np.random.default_rng(seed)
    sample = allrgb[rng.choice(len(allrgb), min(samples, len(allrgb)), replace=False)]
    k = min(n, len(np.unique(sample, axis=0)))
    return KMeans(n_clusters=k, n_init=2, random_state=seed).fit(sample).cluster_centers_


def quantize(rgb: np.ndarray, palette: np.ndarray) -> np.ndarray:
    """Replace every color by its nearest palette color (uint8)."""
    d = ((rgb.astype(np.float32)[:, None, :] - palette[None, :, :].astype(np.float32)) ** 2).sum(-1)
    return np.clip(palette[np.argmin(d, axis=1)] + 0.5, 0, 255).astype(np.uint8)


def _view_cloud(view: DynamicView, config: PreprocessConfig) -> Cloud:
    xyz = np.asarray(view.xyz, dtype=np.float32)
    rgb = np.asarray(view.rgb, dtype=np.uint8)
    if view.normals is not None:
        return Cloud(xyz, rgb, np.asarray(view.normals, dtype=np.float32))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz.astype(np.float64)))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=config.normal_radius, max_nn=30))
    nrm = np.asarray(pcd.normals)
    outward = xyz - np.asarray(view.center, dtype=np.float32)
    nrm[np.sum(nrm * outward, axis=1) < 0] *= -1.0  # a view of a solid object: normals point outward
    return Cloud(xyz, rgb, nrm.astype(np.float32))


def scan_palette(views: list[DynamicView], config: PreprocessConfig) -> np.ndarray:
    """The scan's color palette: fitted on every view, or on the first ``palette_views`` of them."""
    used = views[:config.palette_views] if config.palette_views > 0 else views
    return fit_palette([np.asarray(v.rgb) for v in used], config.color_clusters, config.kmeans_samples, config.seed)


def stacking_frame(view0: DynamicView) -> tuple[np.ndarray, np.ndarray]:
    """(reference centre, unit turn axis) every view is stacked on: view 0's centre and table normal."""
    axis = np.asarray(view0.table.normal, dtype=float)
    return np.asarray(view0.center, dtype=float), axis / np.linalg.norm(axis)


def prepare_view(view: DynamicView, ref_center: np.ndarray, axis: np.ndarray, palette: np.ndarray,
                 config: PreprocessConfig) -> PreparedView:
    """One view pre-rotated, stacked and color-quantised; depends on no other view than through its args."""
    T = prerotation(view, ref_center, axis)
    cloud = _view_cloud(view, config).transformed(T)
    reduced = Cloud(cloud.xyz, quantize(cloud.rgb, palette), cloud.normals)
    return PreparedView(view.index, T, cloud, reduced)


def neighbour_edges(n_views: int) -> list[tuple[int, int]]:
    """(source, target) of the n pair registrations: view i+1 onto view i, and view 0 onto view n-1."""
    return [((i + 1) % n_views, i) for i in range(n_views - 1)] + [(0, n_views - 1)]


def preprocess(views: list[DynamicView], config: PreprocessConfig | None = None,
               regions: bool = False) -> Prepared:
    """Validate, pre-rotate and stack the views, quantise colors and (optionally) pair regions."""
    t0 = time.perf_counter()
    cfg = config or PreprocessConfig()
    validate_views(views)
    ref_center, axis = stacking_frame(views[0])
    palette = scan_palette(views, cfg)
    prepared = [prepare_view(v, ref_center, axis, palette, cfg) for v in views]
    prep = Prepared(prepared, ref_center, axis, {}, palette)
    if regions:
        attach_regions(prep, cfg)
    prep.seconds = time.perf_counter() - t0
    return prep


def view_regions(pv: PreparedView, config: PreprocessConfig) -> list[Cloud]:
    """One prepared view split into regions (on its ``region_voxel`` copy): a function of that view alone
    (fixed seed), so the incremental model segments each view once, as it arrives, exactly as the end would."""
    from services.registration.dynamic import good

    small = pv.reduced.downsampled(config.region_voxel)
    idx = good.segment_regions(small.xyz, small.normals, small.rgb, n_regions=config.n_regions, seed=config.seed)
    return [small.subset(r) for r in idx]


def edge_region_pairs(ps: PreparedView, pt: PreparedView, config: PreprocessConfig) -> list[tuple[int, int]]:
    """The top GOOD region pairs of one edge (source ``ps`` onto target ``pt``): a function of those two views'
    regions only, so an edge's pairs are known as soon as its two views are."""
    from services.registration.dynamic import good

    if not ps.regions or not pt.regions:
        return []
    allp_s = np.vstack([r.xyz for r in ps.regions])
    allp_t = np.vstack([r.xyz for r in pt.regions])
    off_s = np.cumsum([0] + [len(r) for r in ps.regions])
    off_t = np.cumsum([0] + [len(r) for r in pt.regions])
    top = good.top_region_pairs([np.arange(off_s[i], off_s[i + 1]) for i in range(len(ps.regions))],
                                [np.arange(off_t[i], off_t[i + 1]) for i in range(len(pt.regions))],
                                allp_s, allp_t, n_values=config.good_bins, k=config.region_pairs)
    return [(p.index_a, p.index_b) for p in top]


def attach_regions(prep: Prepared, config: PreprocessConfig | None = None) -> Prepared:
    """Segment every view into regions and find the top GOOD region pairs between neighbours (in place).

    Separate from ``preprocess`` so the automatic choice computes regions only if it needs them.
    """
    cfg = config or PreprocessConfig()
    if prep.region_pairs:
        return prep
    for pv in prep.views:
        pv.regions = view_regions(pv, cfg)
    for s, t in neighbour_edges(len(prep.views)):
        prep.region_pairs[(s, t)] = edge_region_pairs(prep.views[s], prep.views[t], cfg)
    return prep

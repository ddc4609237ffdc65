"""The input of the dynamic stage: one isolated, statically registered view per turn of the object.

A view is plain numpy data (points, colors, normals in ``base``) plus what the static stage estimated
about it (table plane, object centre) and what the robot commanded (the cumulative turn). Keeping it
free of open3d objects is what lets views and pair jobs be pickled to other processes or machines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from common.errors import ObjscanError
from common.messages import Plane


class DynamicRegistrationError(ObjscanError):
    """The dynamic stage cannot work with its input (empty view, NaNs, wrong shapes, too few views)."""

    code = "dynamic_registration"


@dataclass
class DynamicView:
    """One isolated object view in ``base`` as the static stage delivers it.

    ``commanded_turn_deg`` is cumulative relative to view 0, positive counter-clockwise about the table
    normal (seen from above), as in ``session.json``. ``T_view0_view_true`` is ground truth (sim only):
    it maps this view's ``base`` points onto where they were in view 0; used only for evaluation.
    """

    xyz: np.ndarray
    rgb: np.ndarray
    table: Plane
    center: np.ndarray
    commanded_turn_deg: float
    normals: np.ndarray | None = None
    index: int = 0
    T_view0_view_true: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def validate(self) -> None:
        """Raise a typed error on anything the pipeline could otherwise crash on or silently misuse."""
        xyz = np.asarray(self.xyz)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise DynamicRegistrationError("view xyz must be (N, 3)", code="bad_shape",
                                           detail={"view": self.index, "shape": list(xyz.shape)})
        if xyz.shape[0] < 50:
            raise DynamicRegistrationError("view has too few points to register", code="empty_view",
                                           detail={"view": self.index, "points": int(xyz.shape[0])})
        if not np.isfinite(xyz).all():
            raise DynamicRegistrationError("view xyz contains NaN or inf", code="bad_value",
                                           detail={"view": self.index})
        rgb = np.asarray(self.rgb)
        if rgb.shape != xyz.shape:
            raise DynamicRegistrationError("view rgb must be (N, 3) like xyz", code="bad_shape",
                                           detail={"view": self.index, "rgb": list(rgb.shape)})
        if self.normals is not None:
            nrm = np.asarray(self.normals)
            if nrm.shape != xyz.shape:
                raise DynamicRegistrationError("view normals must be (N, 3) like xyz", code="bad_shape",
                                               detail={"view": self.index, "normals": list(nrm.shape)})
            if not np.isfinite(nrm).all():
                raise DynamicRegistrationError("view normals contain NaN or inf", code="bad_value",
                                               detail={"view": self.index})
        c = np.asarray(self.center, dtype=float)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise DynamicRegistrationError("view center must be a finite 3-vector", code="bad_value",
                                           detail={"view": self.index})
        n = np.asarray(self.table.normal, dtype=float)
        if n.shape != (3,) or not np.isfinite(n).all() or abs(np.linalg.norm(n) - 1.0) > 1e-3:
            raise DynamicRegistrationError("table normal must be a finite unit 3-vector", code="bad_value",
                                           detail={"view": self.index})
        if not np.isfinite(self.commanded_turn_deg):
            raise DynamicRegistrationError("commanded turn is not finite", code="bad_value",
                                           detail={"view": self.index})


def validate_views(views: list[DynamicView], min_views: int = 3) -> None:
    """Validate a whole scan: enough views, each one well-formed."""
    if len(views) < min_views:
        raise DynamicRegistrationError(f"need at least {min_views} views, got {len(views)}",
                                       code="too_few_views", detail={"views": len(views)})
    for v in views:
        v.validate()


def view_center(footprint_center: np.ndarray, table_normal: np.ndarray, height: float) -> np.ndarray:
    """The one definition of a view's centre, from what the static stage reports: the object's footprint
    centre on the table and its height.

    The dynamic stage stacks the views on this point and ``pair.crop_to_overlap`` projects the unit-sphere
    crop from it, so every path (live scan, incremental model, replay, reconstruct, import, benchmarks) must
    place it the same way: the centre of the object body, the footprint lifted by half the object's height
    along the table normal.
    """
    n = np.asarray(table_normal, dtype=float)
    return np.asarray(footprint_center, dtype=float) + 0.5 * float(height) * n


def view_from_static(result, commanded_turn_deg: float, index: int = 0,
                     T_view0_view_true: np.ndarray | None = None) -> DynamicView:
    """A ``DynamicView`` from the static stage's ``StaticViewResult`` (``services/registration/static``),
    its centre placed by ``view_center`` like every other path's."""
    cloud = result.object_cloud
    center = view_center(result.object_center, result.table.normal, result.object_height)
    xyz = np.asarray(cloud.xyz, dtype=np.float32)
    rgb = np.asarray(cloud.rgb, dtype=np.uint8) if cloud.rgb is not None else np.full(xyz.shape, 128, np.uint8)
    nrm = None if cloud.normals is None else np.asarray(cloud.normals, dtype=np.float32)
    return DynamicView(xyz=xyz, rgb=rgb, normals=nrm, table=result.table, center=center,
                       commanded_turn_deg=float(commanded_turn_deg), index=index,
                       T_view0_view_true=T_view0_view_true)

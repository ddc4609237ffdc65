"""A real turntable sequence (kleenex, PrimeSense): the box stands on the turntable's top, about 13 cm above the
table, and it is the box that is isolated (the turntable is a body of revolution: it shows no turn)."""

from __future__ import annotations

import numpy as np

from services.importer.base_frame import estimate_base_frame
from services.importer.sources import parse_intrinsics, read_frames
from services.registration.api import StaticConfig, register_view
from tests.conftest import shared_data

KLEENEX = "570.3,570.3,320,240"  # the dataset authors' constants (the sequence's README)


def test_a_box_on_a_turntable_is_isolated_on_the_turntables_top():
    seq = shared_data("real_sequences", "kleenex_primesense")
    frames = read_frames(seq, parse_intrinsics(KLEENEX), 0.001, 11, 360, [])  # frames 0, 11, 22
    base = estimate_base_frame(frames)
    frames[0].T_base_camera = base.T_base_camera.copy()
    result = register_view([frames[0]], StaticConfig())
    support = result.figures.get("support_height_m")
    assert support is not None and 0.11 < support < 0.15  # the turntable's top, not the table
    obj = result.object_cloud.xyz.astype(np.float64)
    # the object stands on that top: its points start there and rise by a tissue box's height (~15 cm)
    above = result.table.signed_distance(obj)
    assert above.min() >= 0.0 and np.percentile(above, 2) < 0.02
    assert 0.12 < result.object_height < 0.19
    # a box's footprint (its faces ~12 cm), not the turntable's (~30 cm across)
    extent = np.ptp(obj[:, :2], axis=0)
    assert extent.max() < 0.2, extent

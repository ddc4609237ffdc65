"""``objscan import`` of a RealSense recording: a twin turntable sequence recorded through the software
D435 into a ``.db3`` file (librealsense's own recorder), then imported: intrinsics and depth scale come
from the recording, the table gives ``base``, the turntable's direction is found from the step alone."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_data

pytestmark = pytest.mark.timeout(600)


@pytest.mark.slow  # ~60 s on the shared machine: 8 frames rendered, recorded, isolated, 7 full-circle turn searches
def test_a_recorded_turntable_sequence_imports(tmp_path):
    shared_data("hope", "milk")
    from bench.software_d435 import SoftwareD435Spec, record_db3
    from services.importer.session import ImportConfig, import_sequence
    from services.sim.turntable import TurntableSpec, turntable_frames

    spec = TurntableSpec(object_name="milk", views=8, step_deg=-45.0)  # clockwise seen from above
    K, T_base_camera, frames = turntable_frames(spec)
    # depth rendered in the colour camera: the recording's depth stream is the colour one (identity extrinsics)
    rec = SoftwareD435Spec(color_intrinsics=K, depth_intrinsics=K, T_color_depth=np.eye(4), depth_scale=0.001)
    path = record_db3(tmp_path / "turntable.db3", [(depth, color) for color, depth in frames], rec)
    report = import_sequence(path, tmp_path / "session", None, ImportConfig(turn_step_deg=45.0))
    assert report["views"] == 8 and not report["skipped"]
    assert report["turns"]["direction"] == "cw" and report["turns"]["direction_source"] == "estimated"
    # the step is a strong prior, not a constant: an estimate within its stated uncertainty (default 2 degrees)
    # refines a turn, so each turn is the step within that uncertainty, and the loop closes on a full turn
    turns = np.diff(report["turns"]["cumulative_deg"])
    assert np.all(np.abs(turns + 45.0) <= 2.0 + 1e-9), turns
    loop = report["turns"]["loop"]
    assert report["turns"]["status"] == "closed" and loop["loop_closes"], loop["reasons"]
    assert loop["total_turn_deg"] == pytest.approx(-360.0, abs=1e-6)
    # the camera stands 16 cm above the table (TurntableSpec): base comes from the table plane
    assert abs(report["base_frame"]["camera_height_m"] - spec.camera_height) < 0.01
    fc = report["focal_calibration"]
    assert fc["fx_before"] == pytest.approx(K.fx)  # the recording's own intrinsics
    assert abs(fc["fx_after"] / K.fx - 1.0) < 0.01  # right ones are kept (within 1 %)

"""A mesh in millimetres, scanned as docs/sim.md says: ``objscan scan --object box.ply --scale 0.001 --up-axis y``.

The flags reach the twin two ways, both checked here: the twin a scan starts is started with them
(``twin_args``), and the orchestrator's reset sends them (``object_scale``/``object_up_axis``); the object the
twin then holds has the box's real size in metres, its long side upright."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from common import keys
from common.client import request_sync
from common.launcher import ProcessSpec
from common.messages import Request
from services.cli.cmd_scan import config_params, twin_args
from services.cli.main import build_parser
from services.cli.scan_config import scan_config
from services.orchestrator.config import AcquisitionConfig
from tests.sim.meshes import write_box_ply

pytestmark = pytest.mark.timeout(300)
BOX_MM = (60.0, 150.0, 40.0)  # a carton lying in its file: 150 mm along y, which is its upright axis


def _extent(session, robot: str) -> np.ndarray:
    pts = request_sync(session, keys.sim(robot, "world"), Request(params={"op": "gt_points", "n": 20000}),
                       timeout=60).info["xyz"]
    return np.ptp(np.asarray(pts), axis=0)


def _scan_args(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(["scan", *argv])


def test_scale_and_up_axis_flags_make_the_config_and_the_twins_start_flags(tmp_path):
    mesh = write_box_ply(tmp_path, BOX_MM)
    cfg = scan_config(_scan_args("--object", str(mesh), "--scale", "0.001", "--up-axis", "y"))
    assert cfg.object_scale == 0.001 and cfg.object_up_axis == "y"
    assert config_params(cfg)["object_scale"] == 0.001 and config_params(cfg)["object_up_axis"] == "y"
    assert twin_args(cfg) == ["--object", str(mesh.resolve()), "--scale", "0.001", "--up-axis=y"]
    assert twin_args(AcquisitionConfig(object="milk")) == ["--object", "milk"]  # the twin starts with the scan's object


def test_a_millimetre_mesh_has_its_size_in_metres_in_the_twin(service_group, tmp_path):
    mesh = write_box_ply(tmp_path, BOX_MM)
    cfg = scan_config(_scan_args("--object", str(mesh), "--scale", "0.001", "--up-axis", "y"))
    robot = service_group.robot
    service_group.launch([ProcessSpec("services.sim", [*twin_args(cfg), "--state-file", "none"], service="sim")],
                         timeout=240)
    started = _extent(service_group.session, robot)
    np.testing.assert_allclose(started, [0.060, 0.040, 0.150], atol=0.004)  # metres, the 150 mm side up

    # the orchestrator's reset (services/orchestrator/machine.py) sends the config's units and axis: the same box
    reset = {"op": "reset", "object": str(mesh), "scale": cfg.object_scale, "up_axis": cfg.object_up_axis}
    request_sync(service_group.session, keys.sim(robot, "world"), Request(params=reset), timeout=120)
    np.testing.assert_allclose(_extent(service_group.session, robot), started, atol=0.004)

    # the reset's units are applied, not the held object's: the same file read as half-millimetres is twice as big
    reset = {"op": "reset", "object": str(mesh), "scale": 0.002, "up_axis": "y"}
    request_sync(service_group.session, keys.sim(robot, "world"), Request(params=reset), timeout=120)
    np.testing.assert_allclose(_extent(service_group.session, robot), 2 * started, atol=0.008)

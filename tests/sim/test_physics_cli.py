"""``objscan scan --physics`` and the twin's ``--physics``: the mode reaches the world (mujoco by default for
a scan), and a bad mode is a typed error from the twin."""

from __future__ import annotations

import pytest

from services.cli.main import build_parser
from services.cli.scan_config import scan_config
from services.orchestrator.config import AcquisitionConfig


def test_scan_defaults_to_mujoco_physics_and_accepts_geometric():
    p = build_parser()
    assert scan_config(p.parse_args(["scan", "--object", "milk"])).physics == "mujoco"
    assert scan_config(p.parse_args(["scan", "--physics", "geometric"])).physics == "geometric"
    with pytest.raises(SystemExit):
        p.parse_args(["scan", "--physics", "bullet"])


def test_the_acquisition_config_carries_the_mode_through_its_journal_form():
    cfg = AcquisitionConfig.from_dict({"object": "milk", "physics": "mujoco"})
    assert cfg.physics == "mujoco"
    assert AcquisitionConfig.from_dict(cfg.to_dict()).physics == "mujoco"
    assert AcquisitionConfig().physics == "geometric"  # programmatic callers keep the fast mode

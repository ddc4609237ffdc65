"""A view without an executable grasp ends with the limit that explains it, not a generic failure."""

from __future__ import annotations

import asyncio

import pytest

from services.orchestrator.config import AcquisitionConfig
from services.orchestrator.limits import name_limit
from services.orchestrator.machine import Acquisition, AcquisitionFailed
from services.session_store import SessionStore


@pytest.mark.parametrize(("rejections", "dry", "held", "limit"), [
    ({"too_wide": 9, "collides_with_table": 2}, [], [], "gripper stroke"),
    ({"collides_with_table": 7, "too_wide": 1}, [], [], "no collision-free grasp"),
    ({}, ["line_unreachable"] * 5 + ["collision"], [], "reach"),
    ({}, ["collision"] * 4 + ["unreachable"], [], "no collision-free grasp"),
    ({}, ["unreachable"], ["slip", "slip"], "grasps did not hold"),
    ({}, [], [], "no grasp"),
])
def test_the_limit_is_named_from_what_stood_in_the_way(rejections, dry, held, limit):
    text = name_limit(rejections, dry, held)
    assert text.split(":")[0] == limit
    assert "(" in text or limit == "no grasp"


def test_running_out_of_rescans_names_the_limit(tmp_path):
    acq = Acquisition(None, SessionStore(tmp_path), AcquisitionConfig(max_rescans=0))  # type: ignore[arg-type]
    acq.j.limits = {"3": {"planner": {"too_wide": 12}, "dry_run": [], "grasp": []}}
    with pytest.raises(AcquisitionFailed) as e:
        asyncio.run(acq._rescan(3, "no grasp found (top-down)"))
    assert "limit: gripper stroke" in e.value.message and "106 mm" in e.value.message
    assert e.value.detail["limit"] == "gripper stroke"


class _UnreachableCell:
    """A cell whose arm refuses every dry-run camera pose as out of reach."""

    async def move(self, kind: str, **kwargs) -> None:  # noqa: ANN003
        from common.errors import RemoteError

        raise RemoteError("pose out of reach", code="unreachable")


def test_no_reachable_scan_poses_names_the_reach_limit(tmp_path):
    """The tall box of test_household_meshes ended with a bare "no reachable set of scan poses around the
    object": a reach limit, which the message must name like every other one."""
    acq = Acquisition(_UnreachableCell(), SessionStore(tmp_path), AcquisitionConfig())  # type: ignore[arg-type]
    with pytest.raises(AcquisitionFailed) as e:
        asyncio.run(acq._reachable_scan_set(0))
    assert "limit: reach" in e.value.message and "unreachable x" in e.value.message
    assert e.value.detail["limit"] == "reach"

"""The same scans give bit-identical static registrations, so a physics session is deterministic for
a seed. Open3D 0.20 parallelises on TBB, which ignores ``OMP_NUM_THREADS``: with its default threads the RGB-D
odometry's scan poses differed in their last bits call to call (measured), and a physics session amplified
those bits into other grasps and set-downs. ``common/open3d_threads.py`` bounds Open3D's threads."""

from __future__ import annotations

import numpy as np
import pytest

from common import keys
from common.api import StaticRequest, ViewResult
from common.client import request_sync
from common.launcher import ProcessSpec
from common.open3d_threads import DEFAULT_THREADS, open3d_thread_count
from tests.conftest import shared_data


def test_the_thread_count_follows_omp_num_threads_and_defaults_to_one():
    assert open3d_thread_count({"OMP_NUM_THREADS": "3"}) == 3
    assert open3d_thread_count({}) == DEFAULT_THREADS == 1
    assert open3d_thread_count({"OMP_NUM_THREADS": "0"}) == 1
    assert open3d_thread_count({"OMP_NUM_THREADS": "many"}) == 1


@pytest.fixture(scope="module")
def cream_cheese_view():
    shared_data("hope", "cream_cheese")
    from bench.scenario import simulated_views

    return simulated_views("cream_cheese", views=1, profile="robot-turned", seed=0)[0]


def test_the_registration_service_registers_the_same_scans_identically(service_group, cream_cheese_view):
    service_group.launch([ProcessSpec("services.registration", [], service="registration")], timeout=180)
    replies = []
    for _ in range(3):
        reply = request_sync(service_group.session, keys.REGISTRATION_STATIC,
                             StaticRequest(frames=cream_cheese_view, view=0), timeout=300)
        assert isinstance(reply, ViewResult), reply
        replies.append(reply)
    first = replies[0]
    for other in replies[1:]:
        # exact equality: a last-bit difference is what grew into another session
        assert np.array_equal(other.scan_poses, first.scan_poses), other.scan_poses - first.scan_poses
        assert np.array_equal(other.center, first.center)
        assert np.array_equal(other.cloud.xyz, first.cloud.xyz)

"""Real-time streaming after a stall: the trajectory resumes at its own pace, it is not caught up."""

from __future__ import annotations

import time

import numpy as np

from services.arm.drivers.base import execute
from services.arm.drivers.sim.driver import SimArmDriver
from services.arm.motion import plan_joint_motion


class StallingDriver(SimArmDriver):
    """Takes 0.25 s on one set-point, as a process that was not scheduled for a while."""

    def __init__(self) -> None:
        super().__init__()
        self.log: list[tuple[float, np.ndarray]] = []

    def write_setpoint(self, q: np.ndarray) -> None:
        if len(self.log) == 20:
            time.sleep(0.25)
        super().write_setpoint(q)
        self.log.append((time.perf_counter(), np.asarray(q).copy()))


def test_setpoints_never_advance_faster_than_planned_after_a_stall():
    drv = StallingDriver()
    drv.connect()
    traj = plan_joint_motion(np.zeros(6), np.full(6, 0.6))
    res = execute(drv, traj, rate_hz=100.0, realtime=True)
    assert res.completed
    vmax = 1.0  # the planner's default joint velocity
    t = np.array([s[0] for s in drv.log])
    q = np.array([s[1] for s in drv.log])
    # over any 5 consecutive set-points after the stall, joint travel per wall-clock second stays within
    # the planned velocity (catching up would send ~25 set-points' worth of travel in a few ms)
    for k in range(21, len(t) - 5):
        travel = np.max(np.abs(q[k + 5] - q[k]))
        assert travel <= vmax * (t[k + 5] - t[k]) * 1.2 + 1e-3, k
    assert res.elapsed_s >= traj.duration + 0.2  # the stall made the motion longer, as it must

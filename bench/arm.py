"""``objscan bench arm``: IK solve time, trajectory generation time, pre-motion check cost.

Figures (JSON keys): ``ik_ms_median`` (warm start from a nearby configuration, as when the arm moves
between neighbouring scan poses; target <= 2 ms), ``ik_cold_ms_median`` (no start configuration),
``ik_success_rate``, ``trajectory_ms_median`` (jerk-limited 6-joint Ruckig trajectory),
``linear_trajectory_ms_median`` (10 cm Cartesian line: dense IK + timing), ``collision_ms_per_sample``
and ``state_us_median``. Baseline, measured in the same run on the same poses: pinocchio's textbook CLIK
(``examples/inverse-kinematics.py``: log6 error, damping 1e-12, step 0.1, no joint limits, one seed),
reported as ``ik_baseline_ms_median`` and the ratio ``ik_speedup_vs_baseline``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pinocchio as pin

from services.arm.arm import ArmConfig, ArmController
from services.arm.collision import CollisionWorld
from services.arm.drivers.sim import SimArmDriver
from services.arm.errors import ArmError
from services.arm.kinematics import Kinematics
from services.arm.motion import plan_joint_motion, plan_linear_motion


def _typical_configs(kin: Kinematics, n: int, seed: int = 1) -> list[np.ndarray]:
    """Configurations with the TCP over the table in front of the arm (where scan and grasp poses are)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        q = rng.uniform(np.maximum(kin.lower, -2.0), np.minimum(kin.upper, 2.0))
        p = kin.fk(q)[:3, 3]
        if 0.03 < p[2] < 0.6 and 0.1 < p[0] < 0.7 and abs(p[1]) < 0.4:
            out.append(q)
    return out


def _textbook_clik(kin: Kinematics, T: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, bool]:
    model, data, fid = kin.model, kin.data, kin.frame_id("gripper")
    oMdes = pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())
    q = q0.copy()
    for _ in range(1000):
        pin.forwardKinematics(model, data, q)
        M = pin.updateFramePlacement(model, data, fid)
        iMd = M.actInv(oMdes)
        err = pin.log6(iMd).vector
        if np.linalg.norm(err) < 1e-6:
            return q, True
        J = -pin.Jlog6(iMd.inverse()) @ pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        v = -J.T @ np.linalg.solve(J @ J.T + 1e-12 * np.eye(6), err)
        q = pin.integrate(model, q, v * 0.1)
    return q, False


def _median_ms(times: list[float]) -> float:
    return float(np.median(times) * 1e3) if times else float("nan")


def run(quick: bool = False) -> dict[str, Any]:
    n = 40 if quick else 300
    kin = Kinematics()
    rng = np.random.default_rng(2)
    configs = _typical_configs(kin, n)
    warm, cold, base, ok = [], [], [], 0
    for q in configs:
        T = kin.fk(q)
        q_init = q + rng.normal(0.0, 0.1, 6)
        t = time.perf_counter()
        try:
            kin.ik(T, q_init)
            ok += 1
        except ArmError:
            pass
        warm.append(time.perf_counter() - t)
        t = time.perf_counter()
        try:
            kin.ik(T)
        except ArmError:
            pass
        cold.append(time.perf_counter() - t)
        t = time.perf_counter()
        _textbook_clik(kin, T, q_init)
        base.append(time.perf_counter() - t)

    traj_t, line_t = [], []
    for q0, q1 in zip(configs[:-1], configs[1:], strict=True):
        t = time.perf_counter()
        plan_joint_motion(q0, q1)
        traj_t.append(time.perf_counter() - t)
    for q0 in configs[: (10 if quick else 40)]:
        T1 = kin.fk(q0)
        T1[2, 3] += 0.10  # lift 10 cm
        t = time.perf_counter()
        try:
            plan_linear_motion(kin, q0, T1)
            line_t.append(time.perf_counter() - t)
        except ArmError:
            pass

    world = CollisionWorld(kin)
    t = time.perf_counter()
    for q in configs:
        world.first_contact(q, 0.05)
    col_ms = (time.perf_counter() - t) / len(configs) * 1e3

    ctl = ArmController(SimArmDriver(), ArmConfig(realtime=False), kinematics=kin)
    ctl.connect()
    st = []
    for _ in range(200):
        t = time.perf_counter()
        ctl.state()
        st.append(time.perf_counter() - t)

    ik_ms = _median_ms(warm)
    base_ms = _median_ms(base)
    return {
        "ik_ms_median": ik_ms,
        "ik_ms_p95": float(np.percentile(warm, 95) * 1e3),
        "ik_cold_ms_median": _median_ms(cold),
        "ik_success_rate": ok / len(configs),
        "ik_baseline_ms_median": base_ms,
        "ik_speedup_vs_baseline": base_ms / ik_ms,
        "ik_target_ms": 2.0,
        "trajectory_ms_median": _median_ms(traj_t),
        "linear_trajectory_ms_median": _median_ms(line_t),
        "collision_ms_per_sample": col_ms,
        "state_us_median": float(np.median(st) * 1e6),
        "poses": len(configs),
    }


def main() -> None:
    from bench.report import print_figures

    print_figures("arm", run())


if __name__ == "__main__":
    main()

"""Arm test fixtures: one Kinematics per session (the URDF is parsed once), sim-driven controllers."""

from __future__ import annotations

import numpy as np
import pytest

from services.arm.kinematics import Kinematics

# A camera-up working posture clear of the table, used as the start of most motions.
Q_HOME = np.array([0.0, -0.3, -0.9, 0.0, 1.2, 0.0])


@pytest.fixture(scope="session")
def kin() -> Kinematics:
    return Kinematics()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def random_reachable_q(kin: Kinematics, rng: np.random.Generator, n: int, min_tcp_z: float = 0.05) -> list:
    """Random joint configurations inside the limits whose TCP is above the table: poses the arm can reach."""
    out = []
    while len(out) < n:
        q = rng.uniform(np.maximum(kin.lower, -2.6), np.minimum(kin.upper, 2.6))
        if kin.fk(q)[2, 3] > min_tcp_z:
            out.append(q)
    return out

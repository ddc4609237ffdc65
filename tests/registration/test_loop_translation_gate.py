"""A fixed camera's loop displacement is judged on the session's own noise, an arm's on the fixed gate.

A fixed-camera sequence runs 8-24 pairs of a sensor whose noise grows with the square of the distance;
each pair places its view to within the noise the posed neighbours show (their inlier RMSE), and n such
errors add up around the loop as a random walk. A loop open by a few millimetres after twenty pairs at
1.4 mm of noise is noise; one open by several times sqrt(n) x noise is a wrong pair.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

from services.registration.api import session_dynamic_config
from services.registration.dynamic.configurations import loop_translation_gate_mm, shortfalls


def _outcome(pairs: int, rmse_mm: float, loop_mm: float) -> SimpleNamespace:
    """A configuration whose ``pairs`` posed neighbours agree (agreement 0.95, overlap 0.9, fitness 0.9) at
    ``rmse_mm`` of noise, and whose loop is open by ``loop_mm`` (rotation closed)."""
    consistency = {"posed_rmse_mm": [rmse_mm] * pairs, "posed_agreement": [0.95] * pairs,
                   "posed_overlap": [0.9] * pairs, "posed_fitness": [0.9] * pairs}
    return SimpleNamespace(loop={"rotation_deg": 0.1, "translation_mm": loop_mm}, loop_waived=False, turns=None,
                           consistency=consistency, results=[object()] * pairs)


FIXED = session_dynamic_config({"camera": "fixed"}).accept
ARM = session_dynamic_config({}).accept


def test_a_fixed_cameras_twenty_pair_loop_open_by_its_noise_is_accepted():
    """Twenty pairs at 1.4 mm (a D415 at 0.4 m) and a 7 mm loop: within 3 x sqrt(20) x 1.4 = 18.8 mm."""
    outcome = _outcome(20, 1.4, 7.0)
    assert FIXED.loop_translation_from_noise is True
    assert math.isclose(loop_translation_gate_mm(outcome, FIXED), 3.0 * math.sqrt(20) * 1.4)
    assert shortfalls(outcome, FIXED) == []


def test_a_fixed_cameras_loop_open_beyond_its_noise_is_refused_with_the_figure():
    outcome = _outcome(20, 1.4, 25.0)
    why = shortfalls(outcome, FIXED)
    assert len(why) == 1 and why[0].startswith("loop closure 25.0 mm > 18.8 mm")


def test_a_quieter_sensor_gets_a_tighter_gate():
    """The same 7 mm loop at 0.4 mm of noise is a wrong pair (gate 3 x sqrt(20) x 0.4 = 5.4 mm)."""
    assert shortfalls(_outcome(20, 0.4, 7.0), FIXED)


def test_an_arm_session_keeps_the_fixed_gate():
    assert not ARM.loop_translation_from_noise
    assert shortfalls(_outcome(20, 1.4, 7.0), ARM) == ["loop closure 7.0 mm > 5 mm"]


def test_an_unmeasurable_pair_does_not_widen_the_gate():
    """One pair with no inliers (infinite RMSE) is left out of the median; the others set the noise."""
    outcome = _outcome(12, 1.0, 3.0)
    outcome.consistency["posed_rmse_mm"][4] = float("inf")
    assert math.isclose(loop_translation_gate_mm(outcome, FIXED), 3.0 * math.sqrt(12) * 1.0)

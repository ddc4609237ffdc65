"""An imported (fixed-camera) session's model is judged on what neighbouring views share.

A camera looking at the object from the side sees one or two faces per view; where a box's corner turns past,
half of one view lies on a face the next never sees. Posed fitness (all of a view's points within 3 mm of its
neighbour) then measures that overlap, not the alignment: an imported model is judged on the agreement over the
overlap, and on an overlap large enough to vouch for the pair. An arm session (views from above, the top in
every view) keeps posed fitness.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from services.registration.api import DynamicConfig, session_dynamic_config
from services.registration.dynamic.combine import CombineConfig, pairwise_consistency
from services.registration.dynamic.configurations import AcceptCriteria, shortfalls
from services.registration.dynamic.preprocess import Cloud

STEP = 0.002


def _face(origin, u, v, size_u: float, size_v: float) -> np.ndarray:
    a, b = np.meshgrid(np.arange(0, size_u, STEP), np.arange(0, size_v, STEP), indexing="ij")
    return np.asarray(origin) + np.outer(a.ravel(), u) + np.outer(b.ravel(), v)


def _cloud(xyz: np.ndarray) -> Cloud:
    n = len(xyz)
    return Cloud(xyz.astype(np.float32), np.full((n, 3), 128, np.uint8), np.tile(np.float32([0, 0, 1]), (n, 1)))


def _box_views(shift_mm: float = 0.0) -> SimpleNamespace:
    """Two side views of a 10 cm cube a quarter turn apart: view 0 sees faces A and B, view 1 faces B and C
    (B shared); view 1 moved by ``shift_mm`` along B's normal."""
    x, y, z = np.eye(3)
    a = _face([0, 0, 0], y, z, 0.1, 0.1)  # x = 0
    b = _face([0, 0, 0], x, z, 0.1, 0.1)  # y = 0
    c = _face([0.1, 0, 0], y, z, 0.1, 0.1)  # x = 0.1
    view1 = np.concatenate([b, c]) + np.array([0.0, shift_mm / 1000.0, 0.0])
    views = [SimpleNamespace(reduced=_cloud(np.concatenate([a, b]))), SimpleNamespace(reduced=_cloud(view1))]
    return SimpleNamespace(views=views)


EDGES = [SimpleNamespace(source_view=1, target_view=0), SimpleNamespace(source_view=0, target_view=1)]


def _consistency(shift_mm: float) -> dict:
    return pairwise_consistency(_box_views(shift_mm), [np.eye(4), np.eye(4)], EDGES, CombineConfig())


def _outcome(consistency: dict) -> SimpleNamespace:
    return SimpleNamespace(loop={"rotation_deg": 0.1, "translation_mm": 0.5}, loop_waived=False, turns=None,
                           consistency=consistency)


def test_a_side_views_posed_fitness_is_its_overlap_and_the_agreement_is_the_alignment():
    aligned, shifted = _consistency(0.0), _consistency(5.0)
    # half of each view is on a face the other does not see: posed fitness ~0.5 although the poses are exact
    assert 0.4 < aligned["min_posed_fitness"] < 0.6
    assert 0.4 < aligned["min_posed_overlap"] < 0.6
    assert aligned["min_posed_agreement"] > 0.85  # the unshared face's strip along the shared edge is within 10 mm
    # 5 mm off: the shared face is still within the overlap, and no longer within 3 mm
    assert shifted["min_posed_overlap"] > 0.4 and shifted["min_posed_agreement"] < 0.2


def test_an_imported_session_is_judged_on_the_overlap_and_an_arm_session_on_posed_fitness():
    fixed = session_dynamic_config({"camera": "fixed"}).accept
    arm = session_dynamic_config({}).accept
    assert fixed.judge_overlap is True and not arm.judge_overlap
    # a caller's explicit choice stands
    explicit = DynamicConfig(accept=AcceptCriteria(judge_overlap=False))
    assert session_dynamic_config({"camera": "fixed"}, explicit).accept.judge_overlap is False

    aligned, shifted = _outcome(_consistency(0.0)), _outcome(_consistency(5.0))
    assert not shortfalls(aligned, fixed)  # exact poses: accepted
    assert any("posed agreement over the overlap" in s for s in shortfalls(shifted, fixed))
    assert any(s.startswith("posed fitness") for s in shortfalls(aligned, arm))  # the arm's criterion unchanged


def test_a_pair_that_shares_too_little_cannot_vouch_for_itself():
    c = _consistency(0.0)
    c.update(posed_overlap=[0.1, 0.1], min_posed_overlap=0.1)
    why = shortfalls(_outcome(c), session_dynamic_config({"camera": "fixed"}).accept)
    assert any(s.startswith("posed overlap 0.100") for s in why), why

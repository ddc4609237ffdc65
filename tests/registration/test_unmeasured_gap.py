"""A model that set a view aside must still have measured every turn between the views it kept.

With a pair or a view set aside the loop composition no longer judges the poses; the pose graph places the
views on either side through the rest of the loop. Where those two views overlap as posed, their agreement
vouches for the placement; where they share nothing (a box's views 76 degrees apart once the view between
them is left out), only the full-turn constraint placed them, and the model must not claim acceptance.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from services.registration.api import session_dynamic_config
from services.registration.dynamic.combine import CombineConfig, unmeasured_gaps
from services.registration.dynamic.configurations import shortfalls
from services.registration.dynamic.preprocess import Cloud

STEP = 0.002
X, Y, Z = np.eye(3)


def _face(origin, u, v) -> np.ndarray:
    a, b = np.meshgrid(np.arange(0, 0.1, STEP), np.arange(0, 0.1, STEP), indexing="ij")
    return np.asarray(origin, float) + np.outer(a.ravel(), u) + np.outer(b.ravel(), v)


FACES = {"A": _face([0, 0, 0], Y, Z), "B": _face([0, 0, 0], X, Z), "C": _face([0.1, 0, 0], Y, Z),
         "D": _face([0, 0.1, 0], X, Z)}


def _prep(sees: list[str]) -> SimpleNamespace:
    """Four side views of a 10 cm cube, view k seeing the faces ``sees[k]`` (posed exactly: identity)."""
    views = []
    for k, faces in enumerate(sees):
        xyz = np.concatenate([FACES[f] for f in faces]).astype(np.float32)
        cloud = Cloud(xyz, np.full((len(xyz), 3), 128, np.uint8), np.tile(np.float32([0, 0, 1]), (len(xyz), 1)))
        views.append(SimpleNamespace(reduced=cloud, index=k))
    return SimpleNamespace(views=views)


def _edges(*pairs: tuple[int, int]) -> list[SimpleNamespace]:
    return [SimpleNamespace(source_view=s, target_view=t) for s, t in pairs]


# view 1 left out: the kept edges are 2 -> 3 and the closing 0 -> 3; nothing links 0 and 2
KEPT_EDGES, KEPT = _edges((3, 2), (0, 3)), [0, 2, 3]


def _gaps(sees: list[str]) -> list[dict]:
    return unmeasured_gaps(_prep(sees), [np.eye(4)] * 4, KEPT_EDGES, KEPT, CombineConfig())


def _outcome(gaps: list[dict]) -> SimpleNamespace:
    outliers = SimpleNamespace(no_majority=False, left_out=[{"view": 1}], fitness=[0.99, float("nan"), 0.99, 0.99])
    consistency = {"posed_agreement": [0.95] * 3, "posed_overlap": [0.9] * 3, "posed_fitness": [0.9] * 3,
                   "unmeasured_gaps": gaps}
    return SimpleNamespace(loop={"rotation_deg": 90.0, "translation_mm": 60.0}, loop_waived=True, turns=None,
                           consistency=consistency, outliers=outliers)


def test_kept_neighbours_that_share_nothing_are_an_unmeasured_gap_and_the_model_is_not_accepted():
    gaps = _gaps(["AB", "BC", "CD", "DA"])  # views 0 (A, B) and 2 (C, D) share no face, only the edges' strips
    assert [(g["from"], g["to"]) for g in gaps] == [(0, 2)] and gaps[0]["overlap"] < 0.25
    why = shortfalls(_outcome(gaps), session_dynamic_config({"camera": "fixed"}).accept)
    assert len(why) == 1 and "0 -> 2" in why[0] and "not measured" in why[0]


def test_kept_neighbours_that_overlap_as_posed_vouch_for_the_placement():
    gaps = _gaps(["AB", "BC", "BC", "DA"])  # view 2 sees view 0's face B
    assert len(gaps) == 1 and gaps[0]["overlap"] > 0.4
    assert shortfalls(_outcome(gaps), session_dynamic_config({"camera": "fixed"}).accept) == []

"""The report's interactive model data: what the page carries is the model (to the quantisation step)."""

from __future__ import annotations

import base64
import json
import re

import numpy as np

from services.report.viewer import MAX_POINTS, quantise, viewer_html


def _attr(page: str, name: str) -> str:
    return re.search(rf'data-{name}="([^"]*)"', page).group(1)


def test_positions_and_colours_round_trip_through_the_page():
    rng = np.random.default_rng(1)
    xyz = rng.uniform([-0.05, -0.03, 0.0], [0.05, 0.03, 0.2], size=(3000, 3))
    rgb = rng.integers(0, 255, (3000, 3), dtype=np.uint8)
    err = rng.integers(0, 255, (3000, 3), dtype=np.uint8)
    page = viewer_html(xyz, rgb, err)
    q = np.frombuffer(base64.b64decode(_attr(page, "xyz")), dtype="<u2").reshape(-1, 3)
    lo, hi = np.array(json.loads(_attr(page, "lo"))), np.array(json.loads(_attr(page, "hi")))
    back = lo + (hi - lo) * q / 65535.0
    step = (hi - lo) / 65535.0
    assert np.all(np.abs(back - xyz) <= step / 2 + 1e-12)  # within half a quantisation step (~1.5 µm here)
    assert np.array_equal(np.frombuffer(base64.b64decode(_attr(page, "rgb")), np.uint8).reshape(-1, 3), rgb)
    assert np.array_equal(np.frombuffer(base64.b64decode(_attr(page, "err")), np.uint8).reshape(-1, 3), err)
    assert "error vs ground truth" in page


def test_large_models_are_subsampled_and_no_ground_truth_means_no_error_view():
    xyz = np.random.default_rng(2).normal(size=(MAX_POINTS + 5000, 3))
    page = viewer_html(xyz, None)
    assert len(base64.b64decode(_attr(page, "xyz"))) == MAX_POINTS * 6
    assert "data-err" not in page and "error vs ground truth" not in page


def test_a_flat_model_does_not_divide_by_zero():
    xyz = np.zeros((10, 3))
    xyz[:, 0] = np.linspace(0, 1, 10)
    q, lo, hi = quantise(xyz)
    assert np.isfinite(q).all() and q[:, 1].max() == 0 and q[-1, 0] == 65535

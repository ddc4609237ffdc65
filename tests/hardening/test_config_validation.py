"""``AcquisitionConfig`` validates every field with a clear, typed error.

Why: ``from_dict`` copied whatever it was given: ``views: 3.5`` or NaN left a session ``running`` forever
and ``views: 100000000`` blocked the orchestrator's event loop."""

from __future__ import annotations

import json
import math

import pytest

from services.orchestrator.config import AcquisitionConfig, ConfigError


@pytest.mark.parametrize(("data", "field"), [
    ({"views": 3.5}, "views"), ({"views": math.nan}, "views"), ({"views": 100_000_000}, "views"),
    ({"views": 0}, "views"), ({"views": True}, "views"), ({"turn_deg": math.nan}, "turn_deg"),
    ({"turn_deg": 0}, "turn_deg"), ({"seed": -1}, "seed"), ({"width": 10**6}, "width"), ({"object": ""}, "object"),
    ({"workspace_center": [0.6]}, "workspace_center"), ({"workspace_center": [0.6, math.inf]}, "workspace_center[1]"),
    ({"evaluate": "yes"}, "evaluate"), ({"dynamic_config": []}, "dynamic_config"), ({"nope": 1}, "config"),
    ({"scan": {"distances": []}}, "scan.distances"), ({"scan": {"bogus": 1}}, "scan"), ({"scan": 3}, "scan"),
    ({"turn": {"branch_seeds": [[0, 1]]}}, "turn.branch_seeds[0]"), ({"turn": {"max_checks": 1e9}}, "turn.max_checks"),
])
def test_bad_values_raise_a_typed_error_naming_the_field(data, field):
    with pytest.raises(ConfigError) as err:
        AcquisitionConfig.from_dict(data)
    assert err.value.code == "invalid_config" and err.value.detail["field"] == field


def test_a_config_round_trips_through_json():
    cfg = AcquisitionConfig(views=4, turn_deg=45.0, seed=3)
    assert AcquisitionConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    with pytest.raises(ConfigError):
        AcquisitionConfig(views=2.0)  # the dataclass itself validates, not only from_dict

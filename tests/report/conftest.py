"""One fake finished milk session for every report test module (built once: ~15-40 s on a loaded machine)."""

from __future__ import annotations

import pytest

from tests.conftest import shared_data
from tests.library.fake_session import build_fake_session


@pytest.fixture(scope="session")
def milk_session(tmp_path_factory):
    shared_data("hope", "milk")
    return build_fake_session(tmp_path_factory.mktemp("rep") / "milk", "milk", views=4, turn_deg=90.0)

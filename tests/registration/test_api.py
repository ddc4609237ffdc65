"""The public module resolves every name it offers, and loads nothing heavy until one is used."""

from __future__ import annotations

import subprocess
import sys

import pytest

import services.registration.api as api


def test_every_public_name_resolves():
    missing = [name for name in api.__all__ if getattr(api, name, None) is None]
    assert missing == []
    with pytest.raises(AttributeError):
        api.no_such_name  # noqa: B018 - the attribute access is the test


def test_importing_the_api_loads_no_registration_internals():
    code = ("import sys, services.registration.api; "
            "print(sorted(m for m in sys.modules if m.startswith('services.registration.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert out.stdout.strip() == "['services.registration.api']"

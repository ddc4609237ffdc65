"""The dynamic stage's imports are warmed up while the static stage runs, not paid at ``reconstruct``'s start."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from services.registration.warm_import import WarmImport

pytestmark = pytest.mark.timeout(120)


def test_importing_reconstruct_does_not_import_the_dynamic_stage():
    """scikit-learn (and the SciPy it pulls in) is half of ``objscan reconstruct``'s start-up: the module that
    runs the pipeline leaves it to the warm-up, so the static stage starts without waiting for it."""
    code = ("import json, sys\n"
            "import services.registration.reconstruct\n"
            "print(json.dumps(sorted(m for m in ('sklearn', 'services.registration.dynamic.model',"
            " 'services.registration.dynamic.pair') if m in sys.modules)))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=100, check=True)
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []


def test_a_warm_up_imports_its_modules_and_counts_its_cpu():
    warm = WarmImport(("json.decoder", "services.registration.dynamic.views"))
    assert warm.cpu_s() >= 0.0
    assert "services.registration.dynamic.views" in sys.modules


def test_a_warm_up_that_fails_changes_nothing_but_the_time():
    warm = WarmImport(("services.registration.no_such_module",))
    assert warm.cpu_s() >= 0.0  # no exception: the real import, where the module is used, raises
    with pytest.raises(ModuleNotFoundError):
        __import__("services.registration.no_such_module")

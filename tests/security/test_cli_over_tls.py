"""The CLI honours --connect and the TLS variables: ``objscan capture`` reaches a TLS-only
cell with the identity the environment names, and cannot without it."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from tests.security.tls_cell import TlsCell, identity_env

pytestmark = [pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is needed to make certificates"),
              pytest.mark.slow, pytest.mark.timeout(400)]


def _capture(cell: TlsCell, out, env_extra: dict[str, str]) -> subprocess.CompletedProcess[str]:
    env = {"PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1", "COLUMNS": "200", **env_extra}
    return subprocess.run([sys.executable, "-m", "services.cli", "capture", "--backend", "sim", "--connect",
                           cell.endpoint, "--out", str(out)], capture_output=True, text=True, timeout=240, env=env)


def test_capture_over_tls_with_the_environment_identity(tmp_path):
    cell = TlsCell(tmp_path / "cell")
    try:
        cell.start_router()
        cell.launch(["sim", "arm", "camera"])
        ok = _capture(cell, tmp_path / "frame", identity_env(cell.certs, "orchestrator"))
        assert ok.returncode == 0, ok.stdout[-2000:] + ok.stderr[-2000:]
        assert json.loads(ok.stdout.strip().splitlines()[-1])["valid_depth"] > 0.5
        assert (tmp_path / "frame" / "color.png").is_file()
        refused = _capture(cell, tmp_path / "nothing", {})  # same endpoint, no TLS identity in the environment
        assert refused.returncode != 0 and not (tmp_path / "nothing" / "color.png").exists()
    finally:
        cell.close()

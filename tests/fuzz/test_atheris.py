"""Coverage-guided fuzzing (atheris/libFuzzer) of the decoders, for a bounded time in CI.

Each target runs in its own process for ``OBJSCAN_FUZZ_SECONDS`` (default 20 s for ``decode``, half that
for ``unpack_view``) from a seed corpus of every message type, with libFuzzer's per-input timeout (hangs)
and RSS limit (memory) on. A finding leaves a ``crash-``/``timeout-``/``oom-`` file and a non-zero exit;
the test prints the input (base64) so it can become a regression case in test_codec_regressions.py.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris", reason="atheris is not installed (pip install atheris)")

REPO = Path(__file__).resolve().parents[2]
SECONDS = int(os.environ.get("OBJSCAN_FUZZ_SECONDS", "20"))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    from tests.fuzz.atheris_targets import write_seed_corpus

    folder = tmp_path_factory.mktemp("corpus")
    assert write_seed_corpus(folder) >= 2 * 20
    return folder


@pytest.mark.parametrize(("target", "share"), [("decode", 1.0), ("unpack_view", 0.5)])
def test_fuzz_target_runs_its_budget_without_a_finding(target, share, corpus, tmp_path):
    seconds = max(2, int(SECONDS * share))
    work = tmp_path / "corpus"
    work.mkdir()
    for f in corpus.iterdir():  # libFuzzer adds to the corpus folder: keep the seed one clean
        (work / f.name).write_bytes(f.read_bytes())
    artifacts = tmp_path / "artifacts"
    artifacts.mkdir()
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-m", "tests.fuzz.atheris_targets", target, f"-max_total_time={seconds}",
         "-rss_limit_mb=2048", "-timeout=10", "-max_len=65536", f"-artifact_prefix={artifacts}/", str(work)],
        capture_output=True, text=True, timeout=seconds + 120, cwd=REPO, env=env)
    log = out.stderr[-4000:]
    findings = sorted(p.name for p in artifacts.iterdir())
    assert out.returncode == 0 and not findings, f"fuzzer finding in {target}: {findings}\n{log}"
    runs = re.search(r"Done (\d+) runs", out.stderr)
    assert runs and int(runs.group(1)) > 200, f"the fuzzer barely ran:\n{log}"
    print(f"{target}: {runs.group(1)} runs in {seconds} s, no finding")

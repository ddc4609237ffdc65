"""``objscan scan --config FILE.yaml``: the acquisition config's own keys, validated, with flags over the file;
what the orchestrator receives builds exactly the config that was written."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import uuid
from dataclasses import replace
from pathlib import Path

import pytest
import yaml
import zenoh

from common import keys
from common.codec import decode
from common.messages import Ok
from services.orchestrator.config import AcquisitionConfig, ScanGeometry, TurnMotion

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.timeout(300)


def objscan(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", "COLUMNS": "200", "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "services.cli", *args], capture_output=True, text=True,
                          timeout=240, cwd=cwd, env=env)


class FakeOrchestrator:
    """The orchestrator's ``run`` key as the CLI sees it: records each request's params, answers, then says
    the acquisition is done on the status key (so the command ends)."""

    def __init__(self, session: zenoh.Session, robot: str = keys.DEFAULT_ROBOT):
        self.session, self.robot = session, robot
        self.runs: list[dict] = []
        self._declared = [session.declare_queryable(keys.orchestrator(robot, "run"), self._run),
                          session.liveliness().declare_token(keys.alive("orchestrator", uuid.uuid4().hex[:8]))]

    def _run(self, query: zenoh.Query) -> None:
        params = decode(query.payload.to_bytes()).params
        self.runs.append(params)
        folder = f"/sessions/{params['out']}"
        query.reply(query.key_expr, Ok(info={"session": folder}).encode(),
                    encoding=zenoh.Encoding("application/msgpack"))
        done = Ok(info={"status": "done", "state": "done", "session": folder, "views": 1, "views_done": 1})
        threading.Timer(1.0, lambda: self.session.put(keys.orchestrator(self.robot, "status"), done.encode())).start()

    def close(self) -> None:
        for d in self._declared:
            d.undeclare()


def _written_config() -> AcquisitionConfig:
    return AcquisitionConfig(object="carton", views=6, turn_deg=45.0, workspace_center=(0.55, 0.1), seed=7,
                             physics="geometric", object_scale=0.001, object_up_axis="y", max_rescans=1,
                             dynamic_config={"yaw_refine": {"range_deg": 10.0}},
                             scan=ScanGeometry(distances=(0.4, 0.42, 0.36)),
                             turn=TurnMotion(lift=0.03, branch_seeds=((0.0, -0.3, -0.9, 0.0, 1.2, 0.1),)))


def test_config_file_round_trip_and_flags_override_it(service_group, tmp_path):
    cfg = _written_config()
    path = tmp_path / "scan.yaml"
    path.write_text(yaml.safe_dump(cfg.to_dict()))  # the file a user writes from a config, as YAML
    fake = FakeOrchestrator(service_group.session)
    try:
        res = objscan("scan", "--connect", service_group.endpoint, "--config", str(path), "--out", "a", "--json",
                      cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert json.loads(res.stdout)["status"] == "done"
        assert AcquisitionConfig.from_dict(fake.runs[-1]["config"]) == cfg  # the orchestrator builds the same

        res = objscan("scan", "--connect", service_group.endpoint, "--config", str(path), "--out", "b", "--json",
                      "--views", "3", "--turn-deg", "90", "--workspace-center", "0.5,-0.1", "--scale", "0.01",
                      cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        got = AcquisitionConfig.from_dict(fake.runs[-1]["config"])
        assert got == replace(cfg, views=3, turn_deg=90.0, workspace_center=(0.5, -0.1), object_scale=0.01)
    finally:
        fake.close()


@pytest.mark.parametrize("text, named", [
    ("views: 12\nwhat_is_this: 1\n", "what_is_this"),
    ("views: 12\nscan:\n  distance: 0.4\n", "distance"),
    ("turn_deg: 0\n", "turn_deg"),
    ("workspace_center: [2.0, 0.0]\n", "workspace_center"),
    ("views: [1, 2\n", "not valid YAML"),
    ("- views\n", "must hold a map"),
])
def test_a_bad_config_file_is_one_line_naming_the_key(text, named, tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    res = objscan("scan", "--config", str(path), cwd=tmp_path)
    lines = res.stderr.splitlines()
    assert res.returncode == 2 and len(lines) == 1 and res.stdout == "", res
    assert lines[0].startswith(f"objscan scan: {path}") and named in lines[0], lines[0]
    assert lines[0].endswith("[invalid_config]"), lines[0]

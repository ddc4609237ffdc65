"""deploy/docker-compose.tls.yml: no docker engine here, so check what compose would merge.

Every objscan service in docker-compose.yml is covered, reaches the router over tls/, and is given the CA
plus its own certificate and key only; the router runs the shipped policy from the mounted config.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from services.cli.cmd_certs import IDENTITIES
from tests.support import compose

REPO = Path(__file__).resolve().parents[2]
BASE = yaml.safe_load((REPO / "docker-compose.yml").read_text())
TLS = compose.load(REPO / "deploy" / "docker-compose.tls.yml")  # it uses compose's !override tag
SERVICES = [n for n in BASE["services"] if n != "zenoh-router"]


def test_override_covers_every_service_of_the_base_file():
    assert set(TLS["services"]) == set(BASE["services"])
    assert set(SERVICES) <= set(IDENTITIES)


@pytest.mark.parametrize("name", SERVICES)
def test_service_uses_tls_with_its_own_identity(name):
    svc = TLS["services"][name]
    env = svc["environment"]
    assert env["OBJSCAN_ZENOH_CONNECT"].startswith("tls/zenoh-router:")
    assert env["OBJSCAN_ZENOH_TLS_CERT"] == f"/certs/{name}.pem"
    assert env["OBJSCAN_ZENOH_TLS_KEY"] == f"/certs/{name}.key"
    mounted = {v.split(":")[0] for v in svc["volumes"]}
    assert mounted == {"./deploy/certs/ca.pem", f"./deploy/certs/{name}.pem", f"./deploy/certs/{name}.key"}
    # environment keys of the base file survive the override (merged, not lost)
    base_env = BASE["services"][name].get("environment", {})
    assert set(base_env) <= set(env), set(base_env) - set(env)


def test_router_runs_the_shipped_policy():
    router = TLS["services"]["zenoh-router"]
    assert router["command"][:2] == ["-c", "/etc/objscan/zenoh-router-tls.json5"]
    mounts = dict(v.rsplit(":", 1)[0].split(":", 1) for v in router["volumes"])
    assert mounts["./deploy/zenoh-router-tls.json5"] == "/etc/objscan/zenoh-router-tls.json5"
    assert (REPO / "deploy" / "zenoh-router-tls.json5").is_file()
    assert {"./deploy/certs/router.pem", "./deploy/certs/router.key", "./deploy/certs/ca.pem"} <= set(mounts)

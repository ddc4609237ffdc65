"""Certificates from ``objscan certs`` and the TLS settings services read from the environment."""

from __future__ import annotations

import shutil
import subprocess

import pytest
import zenoh

from common.zenoh_config import TlsSettings, ZenohSettings
from services.cli.cmd_certs import IDENTITIES, CertError, certificate_subject, generate_lab_certs, make_leaf

needs_openssl = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl is needed")


@needs_openssl
def test_every_identity_gets_a_certificate_from_the_lab_ca(tmp_path):
    made = generate_lab_certs(tmp_path)
    assert set(made) == {"ca", "router", *IDENTITIES}
    for ident in IDENTITIES:
        assert certificate_subject(made[ident]).endswith(f"CN = {ident}")
        out = subprocess.run(["openssl", "verify", "-CAfile", str(made["ca"]), str(made[ident])],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        assert (tmp_path / f"{ident}.key").stat().st_mode & 0o077 == 0, "private keys are owner-only"
    text = subprocess.run(["openssl", "x509", "-in", str(made["router"]), "-noout", "-ext", "subjectAltName"],
                          capture_output=True, text=True).stdout
    assert "DNS:zenoh-router" in text and "IP Address:127.0.0.1" in text


@needs_openssl
def test_adding_an_identity_keeps_the_ca(tmp_path):
    generate_lab_certs(tmp_path, ["orchestrator"])
    ca_before = (tmp_path / "ca.pem").read_bytes()
    generate_lab_certs(tmp_path, ["viewer"])
    assert (tmp_path / "ca.pem").read_bytes() == ca_before
    generate_lab_certs(tmp_path, ["viewer"], force=True)
    assert (tmp_path / "ca.pem").read_bytes() != ca_before


@needs_openssl
def test_identity_names_are_checked(tmp_path):
    generate_lab_certs(tmp_path, [])
    with pytest.raises(CertError):
        make_leaf(tmp_path, "../evil", ca_cert=tmp_path / "ca.pem", ca_key=tmp_path / "ca.key")


def test_tls_settings_from_env_round_trip(tmp_path):
    for name in ("ca.pem", "arm.pem", "arm.key"):
        (tmp_path / name).write_text("x")
    env = {"OBJSCAN_ZENOH_CONNECT": "tls/localhost:7447", "OBJSCAN_ZENOH_TLS_CA": str(tmp_path / "ca.pem"),
           "OBJSCAN_ZENOH_TLS_CERT": str(tmp_path / "arm.pem"), "OBJSCAN_ZENOH_TLS_KEY": str(tmp_path / "arm.key")}
    s = ZenohSettings.from_env(env)
    assert s.tls == TlsSettings(ca=env["OBJSCAN_ZENOH_TLS_CA"], cert=env["OBJSCAN_ZENOH_TLS_CERT"],
                                key=env["OBJSCAN_ZENOH_TLS_KEY"])
    assert ZenohSettings.from_env(s.to_env()).tls == s.tls  # children of the launcher get the same identity
    conf = s.to_zenoh()
    assert isinstance(conf, zenoh.Config)
    assert ZenohSettings.from_env({}).tls is None  # the embedded default on loopback runs without TLS


def test_tls_settings_refuse_half_an_identity_and_missing_files(tmp_path):
    with pytest.raises(ValueError):
        ZenohSettings.from_env({"OBJSCAN_ZENOH_TLS_CA": "ca.pem", "OBJSCAN_ZENOH_TLS_CERT": "a.pem"})
    s = ZenohSettings(tls=TlsSettings(ca=str(tmp_path / "missing.pem")))
    with pytest.raises(FileNotFoundError):
        s.to_zenoh()

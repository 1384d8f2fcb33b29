"""Secure defaults and TLS (issue 14; SPEC §7).

``skinet router`` makes random passwords at first start and refuses sessions without
them; services and ``skinet run`` listen on loopback with multicast scouting off
unless told otherwise; with a ``tls/`` endpoint the router makes a CA and
certificates (``cryptography``) and requires clients to present one: a client
without the CA, with a certificate of another CA or with an expired one is refused
with a one-line error, at once.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from services.common.security import (
    USERS, ensure_tls, ensure_users, load_ca, make_ca, make_certificate, tls_connect_config,
)
from services.common.zenoh_config import session_config
from tests.services.conftest import free_port, start_skinet

REPO = Path(__file__).resolve().parents[2]


def test_peers_listen_on_loopback_without_scouting_by_default() -> None:
    peer = session_config("peer")
    assert json.loads(peer.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    assert json.loads(peer.get_json("scouting/multicast/enabled")) is False
    assert json.loads(session_config("router").get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(session_config("peer", listen=["tcp/0.0.0.0:7447"], multicast_scouting=True)
                      .get_json("scouting/multicast/enabled")) is True


def test_secrets_are_made_once_and_kept(tmp_path: Path) -> None:
    first = ensure_users(tmp_path)
    assert sorted(first) == sorted(USERS) and len(set(first.values())) == len(USERS)
    assert all(len(p) >= 32 for p in first.values())
    assert ensure_users(tmp_path) == first
    assert (tmp_path / "users.txt").stat().st_mode & 0o077 == 0
    assert (tmp_path / "monitor.password").read_text().strip() == first["monitor"]
    ensure_tls(tmp_path / "tls", ["router"])
    ca = (tmp_path / "tls" / "ca.pem").read_bytes()
    ensure_tls(tmp_path / "tls", ["router", "monitor"])
    assert (tmp_path / "tls" / "ca.pem").read_bytes() == ca and (tmp_path / "tls" / "monitor.key").exists()


class Router:
    """``skinet router`` in its own process, with its first output line."""

    def __init__(self, *args: str):
        self.proc = start_skinet("router", *args)
        assert self.proc.stdout is not None
        self.line = self.proc.stdout.readline()

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        return self.proc.wait(timeout=10)


@pytest.fixture
def secrets(tmp_path: Path) -> Path:
    return tmp_path / "secrets"


def client_config(endpoint: str, user: str | None, password: str | None, tls: dict | None = None) -> dict:
    config: dict = {"mode": "client", "connect": {"endpoints": [endpoint]}, "scouting": {"multicast": {"enabled": False}}}
    if user is not None:
        config["transport"] = {"auth": {"usrpwd": {"user": user, "password": password}}}
    if tls is not None:
        config.setdefault("transport", {})["link"] = {"tls": tls}
    return config


def open_with(config: dict) -> zenoh.Session:
    c = zenoh.Config()
    for key, value in config.items():
        c.insert_json5(key, json.dumps(value))
    return zenoh.open(c)


def test_skinet_router_requires_the_generated_passwords(secrets: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router("--listen", endpoint, "--secrets", str(secrets))
    try:
        assert router.line.startswith("zenoh router ") and f"users and passwords in {secrets}" in router.line
        password = (secrets / "observer.password").read_text().strip()
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_with(client_config(endpoint, None, None))
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            open_with(client_config(endpoint, "observer", "observer-demo-password"))
        open_with(client_config(endpoint, "observer", password)).close()
    finally:
        assert router.stop() == 0


def refused(config: dict, tmp_path: Path, name: str) -> tuple[float, list[str]]:
    """Run a predictor with ``config``: seconds until it exits, and its stderr lines."""
    path = tmp_path / f"{name}.json5"
    path.write_text(json.dumps(config))
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "services.predictor", "--mode", "client", "--zenoh-config", str(path),
                        "--workers", "1"], cwd=REPO, capture_output=True, text=True, timeout=30)
    assert r.returncode == 1, (r.stdout, r.stderr)
    return time.monotonic() - t0, [line for line in r.stderr.splitlines() if line.strip()]


def test_tls_refuses_clients_without_the_ca_or_with_a_bad_certificate(secrets: Path, tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    router = Router("--listen", endpoint, "--secrets", str(secrets))
    try:
        assert f"TLS certificates in {secrets / 'tls'}" in router.line
        tls = secrets / "tls"
        ensure_tls(tls, ["predictor"])
        make_certificate(tls, "expired", load_ca(tls), expired=True)
        other = tmp_path / "other"
        make_certificate(other, "predictor", make_ca(other, "Another CA"))
        password = ensure_users(secrets)["predictor"]

        good = client_config(endpoint, "predictor", password, tls_connect_config(tls, "predictor"))
        open_with(good).close()
        cases = {
            "no CA": client_config(endpoint, "predictor", password),
            "another CA's certificate": client_config(endpoint, "predictor", password, {
                **tls_connect_config(other, "predictor"), "root_ca_certificate": str(tls / "ca.pem")}),
            "expired certificate": client_config(endpoint, "predictor", password, tls_connect_config(tls, "expired")),
        }
        reasons = {
            "no CA": "this client has no CA certificate (transport/link/tls/root_ca_certificate)",
            "another CA's certificate": "(check the CA and this client's certificate)",
            "expired certificate": "(check the CA and this client's certificate)",
        }
        for name, config in cases.items():
            took, lines = refused(config, tmp_path, name.replace(" ", "_").replace("'", ""))
            assert len(lines) == 1 and lines[0].startswith(
                f"python -m services.predictor: error: cannot open the Zenoh session: the router at {endpoint} "
                "refused the TLS handshake: "), (name, lines)
            assert lines[0].endswith(reasons[name]), (name, lines)
            assert took < 15, f"{name}: refused only after {took:.1f} s"
    finally:
        assert router.stop() == 0

"""Secure defaults and TLS (issue 14; docs/semantics.md §7).

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

from services.common import security
from services.common.security import (
    USERS, ensure_tls, ensure_users, load_ca, make_ca, make_certificate, tls_connect_config,
)
from services.common.zenoh_config import session_config
from skinet.errors import SkinetError
from tests.services.conftest import free_port, start_skinet

REPO = Path(__file__).resolve().parents[2]


def test_peers_listen_on_loopback_without_scouting_by_default() -> None:
    peer = session_config("peer")
    assert json.loads(peer.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    assert json.loads(peer.get_json("scouting/multicast/enabled")) is False
    assert json.loads(session_config("router").get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(session_config("peer", listen=["tcp/0.0.0.0:7447"], multicast_scouting=True)
                      .get_json("scouting/multicast/enabled")) is True


def modes(folder: Path) -> dict[str, int]:
    """Every file under ``folder`` (relative path) with its permission bits."""
    return {str(p.relative_to(folder)): p.stat().st_mode & 0o777 for p in sorted(folder.rglob("*")) if p.is_file()}


def test_secrets_are_made_once_and_kept(tmp_path: Path) -> None:
    first = ensure_users(tmp_path)
    assert sorted(first) == sorted(USERS) and len(set(first.values())) == len(USERS)
    assert all(len(p) >= 32 for p in first.values())
    assert ensure_users(tmp_path) == first
    assert (tmp_path / "monitor.password").read_text().strip() == first["monitor"]
    ensure_tls(tmp_path / "tls", ["router"])
    ca = (tmp_path / "tls" / "ca.pem").read_bytes()
    ensure_tls(tmp_path / "tls", ["router", "monitor"])
    assert (tmp_path / "tls" / "ca.pem").read_bytes() == ca and (tmp_path / "tls" / "monitor.key").exists()
    # Secret files are 0600 (observer.password was 0644), certificates 0644.
    assert modes(tmp_path) == {"users.txt": 0o600, **{f"{u}.password": 0o600 for u in USERS},
                               **{f"tls/{n}.{x}": 0o600 if x == "key" else 0o644
                                  for n in ("ca", "router", "monitor") for x in ("key", "pem")}}


def test_no_password_starts_with_a_dash(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--password -x...`` would be taken for an option (a fresh machine's test run made one, 1 in 64 per user)."""
    made = iter(["-dash", "_fine", "-again", "-more", "plain"] + [f"p{i}" for i in range(len(USERS) + 1)])
    monkeypatch.setattr(security.secrets, "token_urlsafe", lambda n: next(made))
    users = ensure_users(tmp_path)
    assert [users[u] for u in USERS[:2]] == ["_fine", "plain"]
    assert not any(p.startswith("-") for p in users.values())


def test_looser_secret_files_of_older_versions_are_made_0600(tmp_path: Path) -> None:
    ensure_users(tmp_path)
    ensure_tls(tmp_path / "tls", ["router"])
    for name in ("observer.password", "users.txt", "tls/ca.key", "tls/router.key"):
        (tmp_path / name).chmod(0o644)
    ensure_users(tmp_path)
    ensure_tls(tmp_path / "tls", ["router"])
    assert {n: m for n, m in modes(tmp_path).items() if m != 0o600} == {"tls/ca.pem": 0o644, "tls/router.pem": 0o644}


def test_no_certificate_is_made_without_the_ca_key(tmp_path: Path) -> None:
    """A folder with ca.pem but no ca.key (a hand-out, an operator's own CA) keeps its CA:
    what it has is used, a missing certificate is a one-line error, never a new CA."""
    ensure_tls(tmp_path, ["router", "observer"])
    (tmp_path / "ca.key").unlink()
    ca = (tmp_path / "ca.pem").read_bytes()
    ensure_tls(tmp_path, ["router", "observer"])  # nothing missing: the CA key is not needed
    with pytest.raises(SkinetError) as err:
        ensure_tls(tmp_path, ["router", "bridge", "monitor"])
    assert str(err.value) == (f"{tmp_path} has ca.pem but no ca.key: cannot make the certificate of bridge, monitor "
                              "(make it where the CA key is: docs/deployment.md, TLS)")
    assert (tmp_path / "ca.pem").read_bytes() == ca and not (tmp_path / "bridge.pem").exists()


def test_each_service_is_handed_its_own_files_only(tmp_path: Path) -> None:
    vault, out = tmp_path / "vault", tmp_path / "out"
    for name in ("router", "observer", "bridge"):
        (out / name).mkdir(parents=True)
    (out / "observer" / "stale.password").write_text("x")  # not the observer's: removed
    (out / "router" / "hub").mkdir()
    (out / "router" / "hub" / "ca.pem").write_text("kept")  # the router's own (a fleet it joined)
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stderr) == (0, ""), r
    assert r.stdout.splitlines() == [
        "secrets: bridge: bridge.password tls/ca.pem tls/bridge.pem tls/bridge.key",
        "secrets: observer: observer.password tls/ca.pem tls/observer.pem tls/observer.key",
        "secrets: router: users.txt tls/ca.pem tls/router.pem tls/router.key"]
    assert modes(out) == {
        **{f"{u}/{u}.password": 0o600 for u in ("bridge", "observer")},
        **{f"{u}/tls/{n}.pem": 0o644 for u in ("bridge", "observer", "router") for n in ("ca", u)},
        **{f"{u}/tls/{u}.key": 0o600 for u in ("bridge", "observer", "router")},
        "router/users.txt": 0o600, "router/hub/ca.pem": 0o644}
    assert (out / "router" / "users.txt").read_bytes() == (vault / "users.txt").read_bytes()
    assert (vault / "tls" / "ca.key").exists() and not list(out.rglob("ca.key"))
    # A fleet's hub: its router also gets the fleet's link files, never the fleet CA's key.
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out", str(out),
                        "--fleet-hub"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.stdout.splitlines()[-1] == ("secrets: router: users.txt tls/ca.pem tls/router.pem tls/router.key "
                                         "fleet/ca.pem fleet/hub.pem fleet/hub.key fleet/hub.password")
    assert (vault / "fleet" / "ca.key").exists() and not list(out.rglob("ca.key"))
    (out / "nobody").mkdir()
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stderr) == (1, f"python -m services.secrets: error: {out / 'nobody'}: a service's folder "
                                           "is named router or for its user (bridge, monitor, predictor, robot, "
                                           "observer, hub, pilot, operator, goalbox)\n")


def test_a_new_out_folder_gets_a_folder_for_each_service(tmp_path: Path) -> None:
    """Outside compose (which mounts one folder per service), ``--out`` need not exist yet (issue 32, item 8)."""
    vault, out = tmp_path / "vault", tmp_path / "new" / "out"
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stderr) == (0, ""), r
    assert sorted(p.name for p in out.iterdir()) == sorted(["router", *USERS])
    assert len(r.stdout.splitlines()) == 1 + len(USERS)
    assert (out / "operator" / "tls" / "operator.pem").is_file() and not list(out.rglob("ca.key"))
    (tmp_path / "file").write_text("")
    r = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(vault), "--out",
                        str(tmp_path / "file")], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert (r.returncode, r.stderr) == (1, f"python -m services.secrets: error: --out {tmp_path / 'file'} is not a "
                                           "folder\n")


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


def fleet(secrets: Path, *args: str, stdin: str = "") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", "fleet", "--secrets", str(secrets), *args],
                          cwd=REPO, input=stdin, capture_output=True, text=True, timeout=30)


def test_a_hub_links_to_joined_robots_over_mutual_tls_only(tmp_path: Path) -> None:
    """Issue 15: the hub reaches a robot that joined (fleet CA and password) and is
    refused by one that did not; bad fleet input is one line."""
    hub_dir, joined_dir, other_dir = tmp_path / "hub", tmp_path / "robot1", tmp_path / "robot2"
    ports = {"robot1": free_port(), "robot2": free_port()}
    first = [Router("--listen", f"tls/127.0.0.1:{p}", "--secrets", str(d))
             for p, d in ((ports["robot1"], joined_dir), (ports["robot2"], other_dir))]
    for r in first:
        assert r.stop() == 0  # their CAs and passwords exist now
    invitation = fleet(hub_dir, "invite")
    assert invitation.returncode == 0 and json.loads(invitation.stdout).keys() == {"fleet_ca", "hub_password"}
    joined = fleet(joined_dir, "join", stdin=invitation.stdout)
    assert joined.stdout == (joined_dir / "tls" / "ca.pem").read_text()
    assert joined.stderr == "skinet fleet: joined; restart this robot's router to trust the hub\n"
    for name, d in (("robot1", joined_dir), ("robot2", other_dir)):  # the hub trusts both robots' CAs
        assert fleet(hub_dir, "add", "localhost" if name == "robot1" else "127.0.0.1",
                     stdin=(d / "tls" / "ca.pem").read_text()).returncode == 0
    bad = {("join",): ("{}", "skinet: error: the invitation is not the output of `skinet fleet invite` "
                             "(a JSON object with fleet_ca and hub_password)"),
           ("add", "robot9"): ("-----BEGIN CERTIFICATE-----\n", "skinet: error: the CA given for robot 'robot9' "
                                                                  "is not a PEM certificate"),
           ("add", "bad_name"): ("", "skinet: error: robot name 'bad_name' must be the host of its endpoint "
                                     "(letters, digits, '.', '-')")}
    for args, (stdin, line) in bad.items():
        r = fleet(joined_dir, *args, stdin=stdin)
        assert (r.returncode, r.stdout, r.stderr.splitlines()) == (1, "", [line]), args

    robots = [Router("--listen", f"tls/127.0.0.1:{ports['robot1']}", "--secrets", str(joined_dir)),
              Router("--listen", f"tls/127.0.0.1:{ports['robot2']}", "--secrets", str(other_dir))]
    assert "member of a fleet (trusts its hub)" in robots[0].line and "member of a fleet" not in robots[1].line
    hub_port = free_port()
    hub = Router("--listen", f"tls/127.0.0.1:{hub_port}", "--secrets", str(hub_dir), "--robots",
                 f"tls/localhost:{ports['robot1']},tls/127.0.0.1:{ports['robot2']},tls/robot3:7447")
    sessions: list[zenoh.Session] = []
    try:
        assert hub.line == (f"skinet router: robot robot3 (tls/robot3:7447) left out: no {hub_dir}/robots/robot3.pem "
                            f"yet (skinet fleet add robot3, docs/deployment.md)\n")
        lines = [hub.proc.stdout.readline()]
        while not lines[-1].startswith("zenoh router"):
            lines.append(hub.proc.stdout.readline())
        assert "hub of 2 of 3 robots" in lines[-1]
        # Loud links (issue 27): the robot that did not join refuses the hub, which says so at once.
        assert lines[:-1] == [f"skinet router: warning: cannot connect to tls/127.0.0.1:{ports['robot2']}: the router "
                              "refused the TLS handshake: CERTIFICATE_VERIFY_FAILED (check the CA and this client's "
                              "certificate); Zenoh keeps trying in the background\n"], lines
        pool = open_with(client_config(f"tls/127.0.0.1:{hub_port}", "predictor", ensure_users(hub_dir)["predictor"],
                                       tls_connect_config(hub_dir / "tls", "predictor")))
        sessions.append(pool)
        token = pool.liveliness().declare_token("skinet/robot1/alive/predictor/pool1")
        seen = {}
        for name, d in (("robot1", joined_dir), ("robot2", other_dir)):
            s = open_with(client_config(f"tls/127.0.0.1:{ports[name]}", "observer", ensure_users(d)["observer"],
                                        tls_connect_config(d / "tls", "observer")))
            sessions.append(s)
            seen[name] = lambda s=s: [str(r.ok.key_expr) for r in s.liveliness().get("skinet/**", timeout=1) if r.ok]
        deadline = time.monotonic() + 10
        while not seen["robot1"]() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert seen["robot1"]() == ["skinet/robot1/alive/predictor/pool1"]
        assert seen["robot2"]() == [], "a robot that did not join refuses the hub"
        token.undeclare()
    finally:
        for s in sessions:
            s.close()
        for r in (hub, *robots):
            assert r.stop() == 0

"""``skinet client-config`` (issue 27 item 7) against a real router with compose's secrets layout.

The secrets job (``python -m services.secrets``) makes the vault and hands each
service its folder; ``skinet router`` runs the shipped ``docker/zenoh/router.json5``
on the router's folder alone (no CA key there); the monitor and the operator's
commands log in with the files ``skinet client-config`` writes from their own
folders.  Real processes and sockets on 127.0.0.1, no containers.
"""

from __future__ import annotations

import datetime
import json
import os
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from services.common.security import ensure_tls, ensure_users, load_ca, make_ca, make_certificate
from tests.processes import stop_and_show
from tests.services.conftest import free_port, start_skinet

REPO = Path(__file__).resolve().parents[2]
UNKNOWN = ("spot:telop.start: error: unknown transition 'telop.start' of skillset 'spot' "
           "(candidates: teleop.start, teleop.interrupt, stand_up.start, sit_down.start)")


def skinet(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=60)


def client_config(folder: Path, user: str, endpoint: str, output: Path) -> Path:
    r = skinet("client-config", "--secrets", str(folder), "--user", user, "--connect", endpoint, "-o", str(output))
    assert (r.returncode, r.stderr) == (0, ""), r
    assert r.stdout.splitlines() == [
        f"wrote {output}: user {user} at {endpoint} (password, CA, certificate and key of {folder})",
        f"  skinet watch SYSTEM_NAME --zenoh-config {output}"]
    return output


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, str]]:
    """The router and a monitor on compose's layout; yields the folder of the hand-outs and the endpoint."""
    root = tmp_path_factory.mktemp("deployment")
    out = root / "out"
    for name in ("router", "monitor", "observer", "bridge", "pilot", "goalbox"):
        (out / name).mkdir(parents=True)
    job = subprocess.run([sys.executable, "-m", "services.secrets", "--vault", str(root / "vault"), "--out", str(out)],
                         cwd=REPO, capture_output=True, text=True, timeout=60,
                         env={**os.environ, "SKINET_DASHBOARD_GOAL_USER": "goalbox"})  # the goal box's login too
    assert job.returncode == 0, job
    shipped = zenoh.Config.from_file(str(REPO / "docker" / "zenoh" / "router.json5"))
    shipped.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(out / "router" / "users.txt")))
    (root / "router.json").write_text(str(shipped))
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = start_skinet("router", "--zenoh-config", str(root / "router.json"), "--listen", endpoint)
    procs: list[tuple[subprocess.Popen, Path]] = []
    try:
        assert router.stdout is not None
        assert router.stdout.readline().endswith(f"TLS certificates in {out / 'router' / 'tls'}\n")
        # It made nothing: no CA of its own, no password file of its clients.
        assert sorted(str(f.relative_to(out / "router")) for f in (out / "router").rglob("*") if f.is_file()) == [
            "tls/ca.pem", "tls/router.key", "tls/router.pem", "users.txt"]
        monitor_config = client_config(out / "monitor", "monitor", endpoint, root / "monitor.json5")
        log = root / "monitor.log"
        with log.open("wb") as f:
            procs.append((subprocess.Popen([sys.executable, "-m", "services.monitor", "skillsets/spot_arm.toml",
                                            "--mode", "client", "--zenoh-config", str(monitor_config)],
                                           cwd=REPO, stdout=f, stderr=subprocess.STDOUT), log))
        observer = zenoh.open(zenoh.Config.from_file(str(client_config(out / "observer", "observer", endpoint,
                                                                         root / "observer.json5"))))
        try:
            deadline = time.monotonic() + 30
            while not [r for r in observer.liveliness().get("skinet/spot_arm/alive/monitor/*", timeout=1) if r.ok]:
                assert time.monotonic() < deadline, f"no monitor token:\n{log.read_text()}"
                time.sleep(0.2)
        finally:
            observer.close()
        yield out, endpoint
    finally:
        stop_and_show(procs)
        router.terminate()
        router.wait(10)


def test_the_written_configuration_logs_in_as_its_user(deployment: tuple[Path, str], tmp_path: Path) -> None:
    out, endpoint = deployment
    config = client_config(out / "observer", "observer", endpoint, tmp_path / "observer.json5")
    assert config.stat().st_mode & 0o777 == 0o600
    text = config.read_text()
    assert text.startswith("// Zenoh client configuration of user 'observer' for the router at " + endpoint)
    body = json.loads(text.split("\n", 4)[4])  # after the four comment lines
    tls = out / "observer" / "tls"
    assert body["transport"] == {
        "auth": {"usrpwd": {"user": "observer", "password": (out / "observer" / "observer.password").read_text().strip()}},
        "link": {"tls": {"root_ca_certificate": str(tls / "ca.pem"), "enable_mtls": True,
                         "connect_certificate": str(tls / "observer.pem"),
                         "connect_private_key": str(tls / "observer.key")}}}
    assert (body["mode"], body["connect"]) == ("client", {"endpoints": [endpoint]})
    # The monitor answers the observer's check through the shipped access control.
    r = skinet("check", "spot_arm", "spot:telop.start", "-m", "client", "--zenoh-config", str(config))
    assert (r.returncode, r.stdout.strip(), r.stderr) == (1, UNKNOWN, "")


def test_a_certificate_of_another_user_gets_nothing_from_the_router(deployment: tuple[Path, str],
                                                                  tmp_path: Path) -> None:
    """The observer's login with the bridge's certificate (both genuine): the router's
    subjects pair them differently, so the session is refused everything."""
    out, endpoint = deployment
    config = client_config(out / "observer", "observer", endpoint, tmp_path / "observer.json")
    body = json.loads(config.read_text())
    bridge = out / "bridge" / "tls"
    body["transport"]["link"]["tls"].update(connect_certificate=str(bridge / "bridge.pem"),
                                            connect_private_key=str(bridge / "bridge.key"))
    config.write_text(json.dumps(body))
    r = skinet("check", "spot_arm", "spot:telop.start", "-m", "client", "--zenoh-config", str(config),
               "--timeout", "1")
    assert (r.returncode, r.stdout, r.stderr.strip()) == (
        1, "", "skinet: error: no monitor of system 'spot_arm' answered on skinet/spot_arm/check/observer "
               "(no monitor is reachable)")


@pytest.fixture
def vault(tmp_path: Path) -> Path:
    folder = tmp_path / "vault"
    ensure_users(folder)
    ensure_tls(folder / "tls", ["observer", "bridge", "operator"])
    return folder


def _expired(folder: Path) -> str:
    make_certificate(folder / "tls", "observer", load_ca(folder / "tls"), expired=True)
    today = datetime.datetime.now(datetime.timezone.utc)
    return (f"{folder}/tls/observer.pem is valid from {today - datetime.timedelta(days=10):%Y-%m-%d} to "
            f"{today - datetime.timedelta(days=1):%Y-%m-%d} only (a new one: docs/deployment.md, TLS)")


def _foreign(folder: Path) -> str:
    make_certificate(folder / "tls", "observer", make_ca(folder / "other", "Another CA"))
    return f"{folder}/tls/observer.pem is not signed by the CA of {folder}/tls/ca.pem"


def _swapped_key(folder: Path) -> str:
    shutil.copy(folder / "tls" / "bridge.key", folder / "tls" / "observer.key")
    return f"{folder}/tls/observer.key is not the key of {folder}/tls/observer.pem"


def _other_users_certificate(folder: Path) -> str:
    shutil.copy(folder / "tls" / "bridge.pem", folder / "tls" / "observer.pem")
    shutil.copy(folder / "tls" / "bridge.key", folder / "tls" / "observer.key")
    return (f"{folder}/tls/observer.pem is the certificate of 'bridge', not of user 'observer': the router accepts "
            "each user with its own certificate only")


def _missing_key(folder: Path) -> str:
    (folder / "tls" / "observer.key").unlink()
    return (f"{folder}/tls/observer.key is missing (the secrets of user 'observer' are observer.password, "
            "tls/ca.pem, tls/observer.pem and tls/observer.key)")


@pytest.mark.parametrize("spoil", [_expired, _foreign, _swapped_key, _other_users_certificate, _missing_key])
def test_files_the_router_would_refuse_are_refused_in_one_line(vault: Path, tmp_path: Path, spoil) -> None:
    message = spoil(vault)
    r = skinet("client-config", "--secrets", str(vault), "-o", str(tmp_path / "observer.json5"))
    assert (r.returncode, r.stdout, r.stderr.splitlines()) == (1, "", [f"skinet: error: {message}"])
    assert not (tmp_path / "observer.json5").exists()


@pytest.mark.parametrize("args, line", [
    (["--secrets", "nowhere"], "skinet: error: secrets folder nowhere does not exist"),
    (["--connect", "tcp/127.0.0.1:7447"], "skinet: error: --connect 'tcp/127.0.0.1:7447': the router checks "
                                           "certificates on a tls/ endpoint only, e.g. tls/127.0.0.1:7447"),
    (["--connect", "tls/host:99999"], "skinet: error: --connect 'tls/host:99999': port '99999' is not a number "
                                      "from 0 to 65535"),
    (["-o", "observer.yaml"], "skinet: error: observer.yaml: the name must end with .json5 or .json (Zenoh reads "
                              "the format from it)"),
])
def test_bad_arguments_are_refused_in_one_line(vault: Path, tmp_path: Path, args: list[str], line: str) -> None:
    r = skinet("client-config", "--secrets", str(vault), *args, cwd=tmp_path)
    assert (r.returncode, r.stdout, r.stderr.splitlines()) == (1, "", [line])
    assert list(tmp_path.glob("*.json*")) == []


def test_a_routers_folder_without_certificates_says_how_to_get_them(tmp_path: Path) -> None:
    """``skinet router --secrets DIR`` on tcp/ only writes no certificates: said in one line (issue 32, item 8)."""
    ensure_users(tmp_path / "router")
    r = skinet("client-config", "--secrets", str(tmp_path / "router"), "-o", str(tmp_path / "observer.json5"))
    assert (r.returncode, r.stdout, r.stderr.splitlines()) == (1, "", [
        f"skinet: error: {tmp_path / 'router'} has no tls/ folder: a router makes its certificates there when it "
        "listens on a tls/ endpoint (skinet router --secrets DIR --listen tls/0.0.0.0:7447)"])
    help_text = skinet("client-config", "--help").stdout
    assert "the\nfolder of `skinet router --secrets DIR --listen tls/...` serves as it is" in help_text


def test_the_default_output_is_the_users_file_here_and_never_names_the_ca_key(vault: Path, tmp_path: Path) -> None:
    r = skinet("client-config", "--secrets", str(vault), "--user", "bridge", cwd=tmp_path)
    assert r.returncode == 0, r
    text = (tmp_path / "bridge.json5").read_text()
    assert "ca.key" not in text and str(vault / "tls" / "bridge.key") in text
    zenoh.Config.from_file(str(tmp_path / "bridge.json5"))  # Zenoh reads it


def test_an_operators_configuration_says_how_to_send_goals(vault: Path, tmp_path: Path) -> None:
    """The vault's ``operator`` (the role that may send the pilot goals: docs/deployment.md)."""
    r = skinet("client-config", "--secrets", str(vault), "--user", "operator", cwd=tmp_path)
    assert (r.returncode, r.stderr) == (0, ""), r
    assert r.stdout.splitlines() == [
        f"wrote operator.json5: user operator at tls/127.0.0.1:7447 (password, CA, certificate and key of {vault})",
        "  skinet watch SYSTEM_NAME --zenoh-config operator.json5",
        "  skinet goal SYSTEM_NAME GOAL... --drive --zenoh-config operator.json5"]
    body = json.loads((tmp_path / "operator.json5").read_text().split("\n", 4)[4])
    assert body["transport"]["auth"]["usrpwd"] == {"user": "operator",
                                                   "password": (vault / "operator.password").read_text().strip()}


def _post_goal(url: str) -> tuple[int, dict]:
    request = urllib.request.Request(url + "api/goal", data=json.dumps(
        {"op": "goal", "goals": "reach spot:Standing", "mode": "guide"}).encode(), method="POST",
        headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_the_dashboards_goal_box_sends_goals_under_its_own_login(deployment: tuple[Path, str],
                                                                tmp_path: Path) -> None:
    """Behind the shipped access control the page logs in as observer, which may not send goals; its goal box
    may log in as goalbox, of the operator role, with its own secret (issue 32, item 7)."""
    out, endpoint = deployment
    pilot_config = client_config(out / "pilot", "pilot", endpoint, tmp_path / "pilot.json5")
    observer = client_config(out / "observer", "observer", endpoint, tmp_path / "observer.json5")
    procs: list[tuple[subprocess.Popen, Path]] = []
    try:
        log = tmp_path / "pilot.log"
        with log.open("wb") as f:
            procs.append((subprocess.Popen([sys.executable, "-m", "services.pilot", "skillsets/spot_arm.toml",
                                            "--mode", "client", "--zenoh-config", str(pilot_config)],
                                           cwd=REPO, stdout=f, stderr=subprocess.STDOUT), log))
        urls = []
        for name, extra in (("plain", []), ("goalbox", ["--goal-user", "goalbox", "--goal-secrets",
                                                        str(out / "goalbox")])):
            port = free_port()
            log = tmp_path / f"dashboard-{name}.log"
            with log.open("wb") as f:
                procs.append((subprocess.Popen([sys.executable, "-m", "services.dashboard", "skillsets/spot_arm.toml",
                                                "--port", str(port), "--mode", "client", "--zenoh-config",
                                                str(observer), *extra], cwd=REPO, stdout=f, stderr=subprocess.STDOUT),
                              log))
            urls.append(f"http://127.0.0.1:{port}/")
            deadline = time.monotonic() + 30
            while "skinet dashboard: system spot_arm on" not in log.read_text():
                assert time.monotonic() < deadline, log.read_text()
                time.sleep(0.2)
            assert log.read_text().splitlines()[0] == (f"skinet dashboard: system spot_arm on {urls[-1]}" + (
                "; its goal box sends as user goalbox" if extra else ""))
        # The pilot answers the goal box's login once it follows the monitor (its liveliness comes first).
        deadline = time.monotonic() + 60
        while (answer := _post_goal(urls[1]))[0] == 504:
            assert time.monotonic() < deadline, answer
            time.sleep(0.5)
        status, body = answer
        assert (status, body["ok"]) == (200, True), body
        status, body = _post_goal(urls[0])  # the page's own login, observer: the router drops its goal query
        assert (status, body["ok"]) == (504, False)
        assert body["error"].endswith("(or the router refused user 'observer': only operator-role users may send "
                                      "goals)"), body
    finally:
        stop_and_show(procs)

"""Loud connections (issue 27, item 2): an explicit ``--connect`` endpoint that cannot be reached,
or that refuses the login, is reported at once in every mode, peer included, naming the endpoint
and the reason (once: as the error of a command that waits a bounded time for it); the commands that need it
exit 1 after their timeout; ``skinet run`` prints
where it listens and the exact commands that reach it; ``--user`` with ``--connect`` logs in to
a router as a client.

A peer session does not fail to open when it reaches nobody (ZENOH.md): it keeps trying in the
background.  Real processes and sessions on 127.0.0.1.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from services.common.zenoh_config import config_from_args
from skinet_cli.main import build_parser, main
from tests.processes import Watched
from tests.services.conftest import REPO, client_args, free_port, wait_queryable

SYSTEM = str(REPO / "skillsets" / "spot_arm.toml")


def skinet(*args: str) -> Watched:
    return Watched([sys.executable, "-m", "skinet_cli.main", *args], REPO)


def _dead() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


def test_an_unreachable_endpoint_of_a_recording_is_said_at_once_and_not_again(tmp_path: Path) -> None:
    """Peer mode (a command given --connect is a client unless -m peer says so): the old behaviour was no word at
    all, and record's "0 messages written", exit 0; then a warning at once and an error that said it again."""
    endpoint = _dead()
    out = tmp_path / "rec.jsonl"
    proc = skinet("record", "spot_arm", "-o", str(out), "--duration", "8", "--connect", endpoint, "-m", "peer")
    code = proc.wait(60)
    warning = (f"skinet record: warning: cannot connect to {endpoint}: nothing answers there; Zenoh keeps trying in "
               "the background")
    assert proc.lines == [warning, f"skinet record: recording skinet/spot_arm/** to {out}",
                          f"skinet: error: nothing recorded in {out}: no link to {endpoint} came up (the warning "
                          "above says why)"], proc.text
    assert proc.timed[0][0] < proc.timed[-1][0] - 4, f"the warning came late: {proc.timed}"  # not at the end
    assert code == 1, proc.text


@pytest.mark.parametrize("command", [
    ("watch", "spot_arm", "--wait", "1"),
    ("check", "spot_arm", "spot:teleop.start", "--timeout", "1"),
    ("goal", "spot_arm", "reach spot:Standing", "--timeout", "1"),
    ("goal", "spot_arm", "--cancel", "--timeout", "1"),
    ("dashboard", "spot_arm", "--port", "0", "--wait", "1"),
    ("foxglove", "spot_arm", "--port", "0", "--wait", "1"),
    ("replay", "{tmp}/run.jsonl", "--linger", "0"),
    ("demo", "--live", "--linger", "0"),
])
def test_an_unreachable_endpoint_of_a_command_that_waits_is_one_line(command: tuple[str, ...],
                                                                     tmp_path: Path) -> None:
    """Commands that wait a bounded time for their endpoints say it once, as their error (a warning first
    repeated it: goal, dashboard and foxglove did until issue 32); in peer mode (given --connect alone they are clients, which fail at once in one line too)."""
    if command[0] == "replay":
        scenario = str(REPO / "skillsets" / "missions" / "unassisted.toml")
        assert main(["demo", "--core", "--log", str(tmp_path / "logs"), scenario]) == 0
        command = ("replay", str(next((tmp_path / "logs").iterdir())), "--linger", "0")
    endpoint = _dead()
    proc = skinet(*(a.replace("{tmp}", str(tmp_path)) for a in command), "--connect", endpoint, "-m", "peer")
    assert proc.wait(60) == 1
    error = f"skinet: error: cannot connect to {endpoint}: nothing answers there"
    if command[0] in ("dashboard", "foxglove"):  # a served view says where it serves (and the SDK logs) first
        assert [line for line in proc.lines if "cannot connect" in line] == [error], proc.text
        assert proc.lines[-1] == error
    else:
        assert proc.lines == [error]


def test_a_peer_connects_when_the_endpoint_comes_up_later(tmp_path: Path) -> None:
    endpoint = _dead()
    record = skinet("record", "spot_arm", "-o", str(tmp_path / "r.jsonl"), "--count", "1", "--duration", "60",
                    "-e", endpoint, "-m", "peer")
    record.wait_for(lambda text: "keeps trying" in text, "warning")
    run = skinet("run", SYSTEM, "--listen", endpoint, "--duration", "60")
    try:
        assert record.wait(60) == 0, record.text
        assert len((tmp_path / "r.jsonl").read_text().splitlines()) >= 1
    finally:
        run.stop()


def test_a_refused_login_is_reported_in_peer_mode_too(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = skinet("router", "--listen", endpoint, "--secrets", str(tmp_path / "secrets"))
    try:
        router.wait_for(lambda text: "zenoh router" in text, "listening")
        peer = skinet("watch", "spot_arm", "--wait", "3", "-m", "peer", "-e", endpoint, "--user", "observer",
                      "--password", "wrong")
        assert peer.wait(60) == 1
        reason = (f"cannot connect to {endpoint}: the router refused the login: authentication failed for user "
                  "'observer' (check SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, or --user and --password)")
        assert peer.lines == [f"skinet: error: {reason}"]
        # --user with --connect is a client of the router: it fails at once, with the same reason.
        client = skinet("watch", "spot_arm", "--wait", "3", "-e", endpoint, "--user", "observer", "--password", "x")
        assert client.wait(60) == 1
        assert client.lines == [f"skinet: error: cannot open the Zenoh session: the router at {endpoint} refused the "
                                "login: authentication failed for user 'observer' (check SKINET_ZENOH_USER and "
                                "SKINET_ZENOH_PASSWORD, or --user and --password)"]
    finally:
        router.stop()


def test_services_log_an_unreachable_endpoint_and_keep_trying() -> None:
    endpoint = _dead()
    monitor = Watched([sys.executable, "-m", "services.monitor", SYSTEM, "-e", endpoint], REPO)
    try:
        monitor.wait_for(lambda text: "monitoring spot_arm" in text, "monitoring")
        assert any(re.search(rf"skinet.zenoh WARNING cannot connect to {endpoint}: nothing answers there; Zenoh "
                             "keeps trying in the background$", line) for line in monitor.lines), monitor.text
    finally:
        assert monitor.stop() == 0


def test_record_with_no_monitor_is_an_error(router: str, tmp_path: Path) -> None:
    proc = skinet("record", "spot_arm", "-o", str(tmp_path / "r.jsonl"), "--duration", "2", "-m", "client",
                  "-e", router)
    assert proc.wait(60) == 1
    assert proc.lines[-1] == (f"skinet: error: nothing recorded in {tmp_path / 'r.jsonl'}: no monitor of system "
                              "'spot_arm' published anything (no monitor is reachable)")


def test_a_service_given_connect_alone_stays_a_peer(monkeypatch: pytest.MonkeyPatch) -> None:
    from services.monitor.__main__ import build_parser as monitor_parser

    for name in ("SKINET_ZENOH_MODE", "SKINET_ZENOH_USER", "SKINET_ZENOH_CONNECT"):
        monkeypatch.delenv(name, raising=False)
    args = monitor_parser().parse_args([SYSTEM, "-e", "tcp/127.0.0.1:7447"])
    assert config_from_args(args).get_json("mode") == '"peer"'


def test_check_through_a_router_without_user_reaches_its_monitor_every_time(router: str, client, spawn) -> None:
    """Issue 30: ``skinet check --connect ROUTER`` without ``--user`` was a peer and now and then found no
    monitor (3 of 6 tries); a command line given --connect is a client: answered in 5 of 5."""
    spawn("services.monitor", SYSTEM, *client_args(router))
    wait_queryable(client, "skinet/spot_arm/check/x", timeout=60)
    answers = []
    for _ in range(5):
        check = subprocess.run([sys.executable, "-m", "skinet_cli.main", "check", "spot_arm", "spot:init_power.start",
                                "--connect", router, "--no-multicast-scouting", "--timeout", "20"],
                               cwd=REPO, capture_output=True, text=True, timeout=60)
        answers.append((check.returncode, check.stdout.split("\n", 1)[0], check.stderr))
    assert answers == [(3, "spot:init_power.start: WARN at step 0 (STATE NOT LIVE: about the last marking known) "
                           "(prediction stale: explicit and forced constraints only)",
                        "")] * 5


def test_run_prints_where_it_listens_and_lines_that_work() -> None:
    run = skinet("run", SYSTEM, "--duration", "120")
    try:
        run.wait_for(lambda text: "  skinet goal " in text, "ready")  # the banner's last line
        head = next(line for line in run.lines if line.startswith("skinet run: "))
        endpoint = re.fullmatch(r"skinet run: system spot_arm, listening on (tcp/127\.0\.0\.1:\d+); connect with:",
                                head).group(1)
        lines = [line.strip() for line in run.lines if line.startswith("  skinet ")]
        assert lines == [f"skinet watch spot_arm -e {endpoint}", f"skinet dashboard spot_arm -e {endpoint}",
                         f"skinet check spot_arm spot:init_power.start -e {endpoint}",
                         f'skinet goal spot_arm "run spot:init_power" -e {endpoint}   (guided; --drive: the pilot '
                         'sends the commands)']
        watch = subprocess.run([sys.executable, "-m", "skinet_cli.main", *shlex.split(lines[0])[1:], "--once"],
                               cwd=REPO, capture_output=True, text=True, timeout=60)
        assert watch.returncode == 0 and watch.stdout.startswith("SkiNet Live  system spot_arm  step 0"), watch
        check = subprocess.run([sys.executable, "-m", "skinet_cli.main", *shlex.split(lines[2])[1:]],
                               cwd=REPO, capture_output=True, text=True, timeout=60)
        # No bridge has connected: the monitor vouches for nothing yet (docs/semantics.md §7), never a plain allow.
        assert check.returncode == 3 and check.stdout.startswith(
            "spot:init_power.start: WARN at step 0 (STATE NOT LIVE: about the last marking known)"), check
        assert "\n  state_unknown (warn) — the live state is not known" in check.stdout, check
        # A transition that cannot fire now is no allow: its own answer and exit status.
        idle = subprocess.run([sys.executable, "-m", "skinet_cli.main", "check", "spot_arm", "spot:go_to_waypoint.start",
                               "-e", endpoint], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert idle.returncode == 5 and idle.stdout.startswith(
            "spot:go_to_waypoint.start: NOT FIRABLE at step 0 (not enabled at the live marking; if it were: "), idle
    finally:
        assert run.stop() == 0


@pytest.mark.parametrize(("argv", "mode"), [
    (["watch", "s"], "peer"),
    (["watch", "s", "--user", "observer"], "peer"),  # nobody to log in to
    (["watch", "s", "--user", "observer", "-e", "tcp/127.0.0.1:7447"], "client"),
    (["watch", "s", "--user", "observer", "-e", "tcp/127.0.0.1:7447", "-m", "peer"], "peer"),
    (["watch", "s", "-e", "tcp/127.0.0.1:7447"], "client"),  # a command line given --connect: a client
    (["watch", "s", "-e", "tcp/127.0.0.1:7447", "-m", "peer"], "peer"),
])
def test_user_with_connect_means_a_router_client(argv: list[str], mode: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from services.common.zenoh_config import session_mode

    for name in ("SKINET_ZENOH_MODE", "SKINET_ZENOH_USER", "SKINET_ZENOH_CONNECT"):
        monkeypatch.delenv(name, raising=False)
    args = build_parser("watch").parse_args(argv)
    assert session_mode(args, args.connect or [], command=True) == mode
    assert config_from_args(args, command=True).get_json("mode") == f'"{mode}"'


@pytest.mark.parametrize(("flags", "mode"), [([], "client"), (["-m", "peer"], "peer")])
def test_a_configuration_files_mode_is_the_sessions_unless_a_flag_says_otherwise(
        flags: list[str], mode: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A file from ``skinet client-config`` sets ``mode: client``: no ``-m client`` needed beside it."""
    for name in ("SKINET_ZENOH_MODE", "SKINET_ZENOH_USER", "SKINET_ZENOH_CONNECT"):
        monkeypatch.delenv(name, raising=False)
    path = tmp_path / "observer.json5"
    path.write_text('{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7447"] } }\n')
    args = build_parser("watch").parse_args(["watch", "s", "--zenoh-config", str(path), *flags])
    assert config_from_args(args, command=True).get_json("mode") == f'"{mode}"'


def test_run_as_a_client_of_a_router(capsys: pytest.CaptureFixture[str]) -> None:
    from skinet_cli.main import main

    assert main(["run", SYSTEM, "--mode", "client", "--listen", "tcp/127.0.0.1:0"]) == 1
    assert capsys.readouterr().err == ("skinet: error: --listen: a client listens on nothing (--mode client, or "
                                       "--user with --connect); the others connect to its router\n")
    assert main(["run", SYSTEM, "--mode", "client"]) == 1
    assert capsys.readouterr().err == "skinet: error: --mode client needs the router's endpoint: --connect ENDPOINT\n"



def test_watch_with_no_endpoint_says_where_to_find_one() -> None:
    """``skinet run`` listens on a free port: a watch without ``-e`` reaches nothing, and says how to reach it."""
    watch = skinet("watch", "spot_arm", "--once", "--wait", "0.5")
    assert watch.wait(60) == 1
    assert watch.lines == ["skinet: error: no monitor of system 'spot_arm' is alive (no monitor is reachable at all; "
                           "no --connect/-e given: `skinet run` and `skinet demo --live` listen on a free port and "
                           "print the -e ENDPOINT to pass)"]

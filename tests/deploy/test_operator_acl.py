"""Operator views through the shipped ACL router (docs/semantics.md §7): ``skinet watch``, ``skinet check``
and the dashboard log in as the read-only ``observer`` (flags or ``SKINET_ZENOH_*``), the
monitor serves its check and last results under its own role, and a refused login says so.

No containers: the router is the Python wheel with ``docker/zenoh/router.json5``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator

import pytest
import zenoh

from deploy_support import REPO, SYSTEM, Tokens, acl_router_config, free_port, login, passwords, wait_until
from services.monitor import start_monitor
from skinet.system.load import load_system
from skinet.wire import keys
from skinet.wire.codec import decode, encode, validate
from skinet.wire.messages import CheckReply, CheckRequest, Divergences, ResultFeed
from tests.services.test_monitor import Events

SG_AT_RD = "violates it at once: spot go_to_waypoint runs while manipulator arm_status at RD"  # skinet.verify.explain
TO_ARM_AT_RD = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
                ("spot", "stand_up.success.standing"), ("manipulator", "arm_ready.start"),
                ("manipulator", "arm_ready.success.ready")]


STAND_IN: dict[str, Events] = {}  # the deployment's bridge side, for the test that moves it on


@pytest.fixture(scope="module")
def deployment() -> Iterator[str]:
    """ACL router, a monitor logged in as ``monitor``, events from ``bridge`` up to the arm at RD
    (no predictor: every check answer is at least warn, prediction_pending)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint))
    monitor_session, bridge = login(endpoint, "monitor"), login(endpoint, "bridge")
    monitor = start_monitor(monitor_session, load_system(REPO / "skillsets" / "spot_arm.toml")[0], client="monitor")
    tokens = Tokens(bridge)
    try:  # the monitor's token is declared last: once seen, its event subscriber is known too
        wait_until(lambda: bool(tokens.of("monitor")), 10, "the monitor's liveliness token")
        events = STAND_IN["bridge"] = Events(bridge)  # returns once the monitor has synced from it
        for skillset, transition in TO_ARM_AT_RD:
            events.send(skillset, transition)
        wait_until(lambda: monitor.counters.applied == len(TO_ARM_AT_RD), 10, "the events applied")
        yield endpoint
    finally:
        tokens.close()
        monitor.close()
        for s in (bridge, monitor_session, router):
            s.close()


def skinet(*args: str, env: dict[str, str] | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("SKINET_ZENOH_")}
    return subprocess.run([sys.executable, "-m", "skinet_cli.main", *args], cwd=REPO, capture_output=True, text=True,
                          timeout=timeout, env={**clean, **(env or {})})


def zenoh_flags(endpoint: str, user: str | None = "observer", password: str | None = None) -> list[str]:
    flags = ["--mode", "client", "--connect", endpoint, "--no-multicast-scouting"]
    if user is not None:
        flags += ["--user", user, "--password", passwords()[user] if password is None else password]
    return flags


PENDING = "  prediction_pending (warn) — implicit constraints at step 6 are not known yet: its prediction is pending"


def test_check_as_observer(deployment: str) -> None:
    out = skinet("check", SYSTEM, "spot:go_to_waypoint.start", *zenoh_flags(deployment))
    assert out.returncode == 3, out  # warn
    assert out.stdout.splitlines() == ["spot:go_to_waypoint.start: WARN at step 6 (prediction stale: explicit "
                                       "and forced constraints only)",
                                       "  safety_guard: explicit (warn) — " + SG_AT_RD, PENDING]
    out = skinet("check", SYSTEM, "spot:go_to_waypoint.start", "--policy", "strict", *zenoh_flags(deployment))
    assert out.returncode == 4 and out.stdout.splitlines()[1:] == [
        "  safety_guard: explicit (deny) — " + SG_AT_RD, PENDING]
    # Nothing else at risk, but no predictor answers: never a plain allow, even after waiting.
    t0 = time.monotonic()
    out = skinet("check", SYSTEM, "spot:sit_down.start", "--json", "--wait", "1", *zenoh_flags(deployment))
    reply = json.loads(out.stdout)
    assert out.returncode == 3 and time.monotonic() - t0 >= 1.0
    assert (reply["decision"], [r["constraint"] for r in reply["reasons"]]) == ("warn", ["prediction_pending"])
    assert (reply["prediction_stale"], reply["state_stale"]) == (True, False)
    out = skinet("check", SYSTEM, "spot:sit_down.start", "--wait", "31", *zenoh_flags(deployment))
    assert (out.returncode, out.stderr.strip()) == (2, "skinet check: error: argument --wait: expected a number of "
                                                       "seconds from 0 to 30, got '31' (see skinet check --help)")
    out = skinet("check", SYSTEM, "spot:sit_down.start", "--policy", "state_unknown=allow", *zenoh_flags(deployment))
    assert (out.returncode, out.stderr.strip()) == (1, "skinet: error: check policy 'state_unknown=allow': "
                                                       "state_unknown can only be warn or deny (the monitor never "
                                                       "allows what it cannot vouch for)")
    out = skinet("check", SYSTEM, "arm:x.start", *zenoh_flags(deployment))
    assert (out.returncode, out.stdout.strip()) == (1, "arm:x.start: error: unknown skillset 'arm' (candidates: "
                                                       "manipulator, spot)")
    out = skinet("check", "other", "spot:x.start", "--timeout", "0.5", *zenoh_flags(deployment))
    assert (out.returncode, out.stderr.strip()) == (1, "skinet: error: no monitor of system 'other' answered on "
                                                       "skinet/other/check/observer (systems with a monitor: spot_arm)")


def test_check_flood_is_limited_per_user(deployment: str) -> None:
    """An observer asking checks as fast as it can gets its budget (20/s, burst 20), then
    "rate limited" at once; another user's checks are still answered (issue 14)."""
    observer, robot = login(deployment, "observer"), login(deployment, "robot")
    payload = encode(CheckRequest(skillset="spot", transition="sit_down.start"))

    def ask(session: zenoh.Session, user: str) -> CheckReply:
        replies = [r for r in session.get(keys.check(SYSTEM, user), payload=payload, timeout=5.0)]
        assert len(replies) == 1 and replies[0].ok is not None, replies
        return decode(replies[0].ok.payload.to_bytes(), CheckReply)

    try:
        start = time.monotonic()
        answers = [ask(observer, "observer") for _ in range(100)]
        elapsed = time.monotonic() - start
        allowed = [a for a in answers if a.ok]
        refused = [a for a in answers if not a.ok]
        assert 20 <= len(allowed) <= 20 + 20 * elapsed + 1, (len(allowed), elapsed)
        assert {a.error for a in refused} == {"rate limited: client 'observer' exceeds 20 requests/s (burst 20)"}
        assert all(a.decision == "warn" for a in allowed)  # no predictor: prediction_pending
        other = ask(robot, "robot")
        assert (other.ok, other.decision) == (True, "warn")
    finally:
        observer.close()
        robot.close()
        time.sleep(1.0)  # the observer's bucket refills for the next tests


def test_watch_logs_in_from_the_environment(deployment: str) -> None:
    env = {"SKINET_ZENOH_USER": "observer", "SKINET_ZENOH_PASSWORD": passwords()["observer"]}
    out = skinet("watch", SYSTEM, "--once", "--wait", "3", *zenoh_flags(deployment, None), env=env)
    assert out.returncode == 0, out
    lines = out.stdout.splitlines()
    assert lines[0].startswith("SkiNet Live  system spot_arm  step 6  last event manipulator:arm_ready.success.ready")
    assert "  manipulator  mutex=Free arm_status=RD; running: -" in lines
    assert "unsafe transitions (1), prediction STALE (explicit and forced constraints only)" in lines  # no predictor here
    assert "services  monitor: 1, bridge_ros2: 1, predictor: 0, pilot: off" in lines
    assert lines[-2:] == ["violations (0)", "divergences and manager restarts (0)"]
    out = skinet("watch", "nope", "--wait", "1", *zenoh_flags(deployment))
    assert (out.returncode, out.stderr.strip()) == (1, "skinet: error: no monitor of system 'nope' is alive "
                                                       "(systems with a monitor: spot_arm)")


@pytest.mark.parametrize("command", [["watch", SYSTEM], ["check", SYSTEM, "spot:teleop.start"],
                                     ["record", SYSTEM, "-o", "/dev/null"], ["dashboard", SYSTEM, "--port", "0"]])
def test_refused_logins_say_so(deployment: str, command: list[str]) -> None:
    port = deployment.rsplit(":", 1)[1]
    out = skinet(*command, *zenoh_flags(deployment, "observer", "wrong"))
    assert out.returncode == 1
    assert out.stderr.strip().endswith(
        f"error: cannot open the Zenoh session: the router at tcp/127.0.0.1:{port} refused the login: "
        "authentication failed for user "
        "'observer' (check SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, or --user and --password)")
    out = skinet(*command, *zenoh_flags(deployment, None))
    assert out.returncode == 1
    assert out.stderr.strip().endswith(
        f"error: cannot open the Zenoh session: the router at tcp/127.0.0.1:{port} refused the login: "
        "it requires a user and password "
        "(set SKINET_ZENOH_USER and SKINET_ZENOH_PASSWORD, or --user and --password)")


def test_dashboard_joins_late_as_observer(deployment: str, tmp_path) -> None:
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "services.dashboard", SYSTEM, "--port", str(port),
                             *zenoh_flags(deployment)], cwd=REPO, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr.readline().strip() == f"skinet dashboard: system {SYSTEM} on http://127.0.0.1:{port}/"

        def snapshot() -> dict:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/snapshot", timeout=2) as r:
                return json.load(r)

        wait_until(lambda: (snapshot()["unsafe"] or {}).get("seq") == 6, 10, "the monitor's last step")
        snap = snapshot()
        assert snap["state"]["skillsets"]["manipulator"]["resources"]["arm_status"] == "RD"
        assert [(e["transition"], e["property"]) for e in snap["unsafe"]["unsafe"]] == [
            ("go_to_waypoint.start", "safety_guard")]
        assert sorted(snap["alive"]) == ["bridge_ros2", "monitor"] and len(snap["alive"]["monitor"]) == 1
        # An observer may not fetch model bundles (issue 14's ACL): given a name, the page
        # draws its lanes from what the monitor publishes, and knows no digest.
        assert snap["model"]["digest"] is None
    finally:
        proc.terminate()
        proc.wait(10)


def test_watch_on_a_terminal_redraws_the_view(deployment: str) -> None:
    import pty

    leader, follower = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "watch", SYSTEM, "--duration", "3",
                             *zenoh_flags(deployment)], cwd=REPO, stdout=follower, stderr=follower)
    os.close(follower)
    out = b""
    while True:
        try:
            chunk = os.read(leader, 65536)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        out += chunk
    os.close(leader)
    assert proc.wait(15) == 0
    text = out.decode()
    assert text.startswith("\x1b[H\x1b[JSkiNet Live  system spot_arm  step 6  last event "
                           "manipulator:arm_ready.success.ready#2"), text[:200]
    assert "services  monitor: 1, bridge_ros2: 1, predictor: 0, pilot: off" in text


RESTARTED = "manager restarted (the manager (or its gateway) came back); same state as before"


def test_observers_receive_the_divergence_list_and_get_it_late(deployment: str) -> None:
    """Issue 27 item 4 through the shipped ACL: the monitor publishes its list of divergences and manager
    restarts, an observer receives it (on its key, and in a round of the monitor's feed), and one that asks later
    gets the list so far."""
    observer = login(deployment, "observer")
    lists: list[Divergences] = []
    sub = observer.declare_subscriber(keys.divergences(SYSTEM),
                                      lambda s: lists.append(decode(s.payload.to_bytes(), Divergences)))
    rounds: list[ResultFeed] = []  # the monitor's feed: the same list, in a round
    feed = observer.declare_subscriber(keys.feed(SYSTEM),
                                       lambda s: rounds.append(decode(s.payload.to_bytes(), ResultFeed)))
    try:
        time.sleep(0.3)  # the subscription reaches the router
        standing = {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"},
                    "running": []}
        STAND_IN["bridge"].send("spot", None, status=standing, restart=True, info=RESTARTED)  # same state: no step
        wait_until(lambda: bool(lists), 10, "the list")
        [entry] = lists[-1].entries
        assert (entry.kind, entry.seq, entry.skillset, entry.reason, entry.info) == ("restart", 6, "spot", "", RESTARTED)
        late = [decode(r.ok.payload.to_bytes(), Divergences) for r in observer.get(keys.divergences(SYSTEM), timeout=5)
                if r.ok is not None]
        assert late == [lists[-1]]
        wait_until(lambda: any(r.kind == "divergences" for f in rounds for r in f.results), 10, "the list in a round")
        assert [validate(r.message, Divergences) for f in rounds for r in f.results if r.kind == "divergences"] == [
            lists[-1]]
    finally:
        feed.undeclare()
        sub.undeclare()
        observer.close()


def test_watch_in_a_pipe_prints_one_line_per_step(deployment: str) -> None:
    """Last in this file: it moves the deployment on (the transfer with the arm at RD)."""
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "watch", SYSTEM, "--duration", "60",
                             *zenoh_flags(deployment)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    events = STAND_IN["bridge"]
    try:
        first = proc.stdout.readline().strip()
        assert first.startswith("[6] manipulator:arm_ready.success.ready#2 | action_guard=ok safety_guard=ok | "
                                "unsafe: spot:go_to_waypoint.start(safety_guard explicit)")
        assert first.endswith("prediction stale"), first  # every skillset live: nothing more said
        restart = proc.stdout.readline().strip()  # the monitor's list so far: the watch joined late
        assert re.fullmatch(rf"MANAGER RESTART at step 6 \(\d\d:\d\d:\d\d\): spot:status#\d+: {re.escape(RESTARTED)}",
                            restart), restart
        events.send("spot", "go_to_waypoint.start")
        line = proc.stdout.readline().strip()
        # spot#6: the restart of the test above was spot#5
        assert line.startswith("[7] spot:go_to_waypoint.start#6 | action_guard=ok safety_guard=VIOLATED | "), line
        events.close()  # the bridge goes: the same step again, with the state stale
        line = proc.stdout.readline().strip()
        if "STATE STALE" not in line:  # the bridge's token went first (services alive: one line more)
            line = proc.stdout.readline().strip()
        assert re.fullmatch(r"\[7\] spot:go_to_waypoint.start#6 \| .* \| STATE STALE: spot lost since "
                            r"\d\d:\d\d:\d\d, manipulator lost since \d\d:\d\d:\d\d", line), line
    finally:
        proc.terminate()
        assert proc.wait(15) == 0

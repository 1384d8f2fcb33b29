"""Several robots sharing one off-board predictor pool, in containers (docs/semantics.md §7).

Two robots, each a compose project of the ``onboard`` profile (router, bridge,
monitor) on its own Docker networks, with a system file of its own name; one
compose project of the ``fleet`` profile (the hub router and two pool predictors)
on a third.  The links are a fourth network, which the hub and each robot's router
join, the routers under the alias the hub connects to (``docker network connect
--alias robotN``).  Cutting a link is ``docker network disconnect`` of that
robot's router.  Events come from the host, logged in as ``bridge`` on the robot's
published port; an observer per robot reads its reports.

Every link is mutual TLS with the secrets each deployment's job made at its first
start (the robots' ``secrets``, the hub's ``fleet-secrets``): the robots join the hub with the commands of docs/deployment.md ("Fleet": ``skinet
fleet invite``, ``join``, ``add`` through ``compose exec``, then restarts).
"""

from __future__ import annotations

import os
import re
import subprocess
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import zenoh

from deploy_support import Tokens, free_port, wait_until
from skinet.wire import keys
from skinet.wire.codec import decode
from skinet.wire.messages import UnsafeReport, Verdicts
from test_containers import SECRETS_IN_IMAGE, Stack, image  # noqa: F401  (the image fixture; skips without Docker)
from test_fleet_links import fleet_skillsets
from skinet.system.load import load_system
from tests.bridge_side import BridgeSide

pytestmark = pytest.mark.slow
ROBOTS = ("robot1", "robot2")
TWIN_ERROR = (r"python -m services\.monitor: error: system 'robot1' is already monitored by {} on this Zenoh network: "
              r"give each robot its own system name \(\[system\] name in its \.toml\)")
LEFT_OUT = ("skinet router: robot {0} (tls/{0}:7447) left out: no /var/lib/skinet/secrets/robots/{0}.pem yet "
            "(skinet fleet add {0}, docs/deployment.md)")


class Robot:
    """One robot's compose project, its observer session and an event source on its router."""

    def __init__(self, name: str, stack: Stack, port: int, skills: Path):
        self.name, self.stack, self.endpoint, self.skills = name, stack, f"tls/127.0.0.1:{port}", skills
        self.synced = False
        self.items: list[tuple[float, object]] = []
        self.session: zenoh.Session | None = None

    def login(self, folder: Path, user: str) -> zenoh.Session:
        """A host session of ``user`` with the password and certificate of this robot's secrets
        (``skinet client-config`` on the files of the service that uses them)."""
        config = zenoh.Config.from_file(str(self.stack.client_config(user, folder, self.endpoint)))
        config.insert_json5("connect/timeout_ms", "60000")  # the router may still be restarting
        return zenoh.open(config)

    def connect(self, folder: Path) -> None:
        self.session = self.login(folder, "observer")
        self.bridge = self.login(folder, "bridge")
        system = self.skills / f"{self.name}.toml"  # the bridge's side, the monitor syncs from (docs/semantics.md §7)
        self.events = BridgeSide(self.bridge, self.name, model=load_system(system)[0] if system.exists() else None,
                                 wait=False)
        self.tokens = Tokens(self.session)
        self._subs = [self.session.declare_subscriber(keys.unsafe(self.name), self._on(UnsafeReport)),
                      self.session.declare_subscriber(keys.verdicts(self.name), self._on(Verdicts))]

    def _on(self, kind: type) -> Callable[[zenoh.Sample], None]:
        return lambda s: self.items.append((time.monotonic(), decode(s.payload.to_bytes(), kind)))

    def send(self, skillset: str, transition: str) -> float:
        """Send one event once the monitor has synced; returns when it was sent."""
        if not self.synced:
            self.events.synced(60)
            self.synced = True
        sent = time.monotonic()
        self.events.send(skillset, transition)
        return sent

    def report(self, seq: int, fresh: bool | None = None) -> tuple[float, UnsafeReport] | None:
        for t, m in list(self.items):
            if isinstance(m, UnsafeReport) and m.seq == seq and (fresh is None or m.prediction_stale != fresh):
                return t, m
        return None

    def verdicts(self, seq: int) -> tuple[float, Verdicts] | None:
        return next(((t, m) for t, m in list(self.items) if isinstance(m, Verdicts) and m.seq == seq), None)

    def router(self) -> str:
        (router,) = self.stack.containers("router")
        return router

    def close(self) -> None:
        if self.session is not None:
            self.tokens.close()
            self.bridge.close()
            self.session.close()


def _docker(*args: str) -> None:
    subprocess.run(["docker", *args], check=True, capture_output=True, timeout=60)


def _entries(report: UnsafeReport) -> list[tuple]:
    return sorted((e.skillset, e.transition, e.property, e.constraint) for e in report.unsafe)


def _secrets_made(stack: Stack, service: str) -> bool:
    """Whether the router (or hub) has its certificate, handed out by the compose job."""
    return stack.compose("exec", "-T", service, "test", "-e", f"{SECRETS_IN_IMAGE}/tls/router.key",
                         check=False).returncode == 0


def join(hub: Stack, robots: list[Stack], names: list[str]) -> None:
    """docs/deployment.md's exchange: the hub's invitation to each robot, each robot's CA to the hub."""
    invitation = hub.compose("exec", "-T", "hub", "skinet", "fleet", "invite").stdout

    def one(name: str, robot: Stack) -> None:
        ca = robot.compose("exec", "-T", "router", "skinet", "fleet", "join", input=invitation).stdout
        assert ca.startswith("-----BEGIN CERTIFICATE-----"), ca
        robot.compose("restart", "-t", "2", "router")
        hub.compose("exec", "-T", "hub", "skinet", "fleet", "add", name, input=ca)

    side_by_side([lambda n=n, r=r: one(n, r) for n, r in zip(names, robots)])
    hub.compose("restart", "-t", "2", "hub")


def side_by_side(calls: list[Callable[[], object]]) -> None:
    """Run ``calls`` in threads (compose commands mostly wait on the engine); the first error is raised."""
    with ThreadPoolExecutor(len(calls)) as pool:
        for future in [pool.submit(c) for c in calls]:
            future.result()


@pytest.fixture(scope="module")
def fleet(image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Stack, str, dict[str, Robot]]]:
    skills = fleet_skillsets(tmp_path_factory.mktemp("fleet") / "skillsets", *ROBOTS)
    for path in (skills, *skills.rglob("*")):  # readable by the containers' user
        path.chmod(0o755 if path.is_dir() else 0o644)
    env = {**os.environ, "SKINET_IMAGE": image, "SKINET_SKILLSETS": str(skills), "SKINET_LOG_LEVEL": "INFO"}
    tag = f"skinet-i15-{os.getpid()}"
    net = f"{tag}-links"
    hub = Stack(f"{tag}-hub", {**env, "COMPOSE_PROFILES": "fleet", "SKINET_HUB_PORT": f"127.0.0.1:{free_port()}",
                               "SKINET_PREDICTORS": "2",
                               "SKINET_FLEET_ROBOTS": "tls/robot1:7447,tls/robot2:7447,tls/robot3:7447"})
    robots = {}
    for name in (*ROBOTS, "robot3"):
        port = free_port()
        robots[name] = Robot(name, Stack(f"{tag}-{name}", {
            **env, "COMPOSE_PROFILES": "onboard", "SKINET_ROUTER_PORT": f"127.0.0.1:{port}",
            "SKINET_TLS_HOSTNAMES": name,  # the name the hub reaches it by, in its router's certificate
            "SKINET_DASHBOARD_PORT": str(free_port()),  # each robot its own dashboard port
            # robot3 is a twin: it runs robot1's system file (its monitor started by its test)
            "SKINET_SYSTEM": f"skillsets/{'robot1' if name == 'robot3' else name}.toml"}), port, skills)
    t0 = time.monotonic()
    try:
        side_by_side([*(lambda n=n: robots[n].stack.compose("up", "-d", "--no-build", timeout=180) for n in ROBOTS),
                      lambda: robots["robot3"].stack.compose("up", "-d", "--no-build", "router", timeout=180),
                      lambda: hub.compose("up", "-d", "--no-build", timeout=180)])
        for s, service in [(r.stack, "router") for r in robots.values()] + [(hub, "hub")]:
            wait_until(lambda s=s, service=service: _secrets_made(s, service), 90, f"{s.project}: secrets")
        # Before joining, the hub leaves every robot out, one line each.
        wait_until(lambda: all(LEFT_OUT.format(n) in hub.logs() for n in robots), 30, "the hub's notes")
        join(hub, [r.stack for r in robots.values()], list(robots))
        # The robots' links: a network of their own, `--internal` so that it never becomes
        # a container's default gateway (that would move the routers' published ports,
        # and with them this host's sessions, to the network the test cuts).
        _docker("network", "create", "--internal", net)
        (hub_router,) = hub.containers("hub")
        _docker("network", "connect", net, hub_router)
        for name in ROBOTS:
            _docker("network", "connect", "--alias", name, net, robots[name].router())
        for name, r in robots.items():
            r.connect(tmp_path_factory.mktemp(f"secrets-{name}"))
        print(f"fleet up and joined in {time.monotonic() - t0:.0f} s")
        yield hub, net, robots
    finally:
        for r in robots.values():
            r.close()
        stacks = (*(r.stack for r in robots.values()), hub)
        for s in stacks:
            print(f"--- logs of {s.project} ---\n{s.logs()}")
        side_by_side([s.down for s in stacks])
        subprocess.run(["docker", "network", "rm", net], capture_output=True, timeout=60)


def test_robots_share_the_pool_and_a_cut_link_affects_only_its_robot(fleet) -> None:
    hub, net, robots = fleet
    r1, r2 = robots["robot1"], robots["robot2"]
    for r in (r1, r2):
        wait_until(lambda r=r: len(r.tokens.of("predictor")) == 2 and r.tokens.of("monitor"), 120,
                   f"{r.name}: its monitor and the pool's two predictors")
    # Both robots step; both predictions come from the pool (the first ones of step 0 may
    # have been published before the observers subscribed).
    for r in (r1, r2):
        r.send("spot", "init_power.start")
    for r in (r1, r2):
        wait_until(lambda r=r: r.report(1, fresh=True) is not None, 60, f"{r.name}: fresh step 1")

    _docker("network", "disconnect", net, r1.router())
    cut = time.monotonic()
    # robot2 is not affected: every step fresh within a few seconds.
    for step, transition in ((2, "init_power.success.powered_on"), (3, "stand_up.start")):
        sent = r2.send("spot", transition)
        wait_until(lambda s=step: r2.report(s, fresh=True) is not None, 5, f"robot2: fresh step {step} during the cut")
        assert r2.report(step, fresh=True)[0] - sent < 5.0
    # robot1 keeps its verdicts and explicit constraints, on time, predictions stale.
    sent = r1.send("spot", "init_power.success.powered_on")
    wait_until(lambda: r1.verdicts(2) is not None and r1.report(2) is not None, 5, "robot1: step 2 during the cut")
    at, stale = r1.report(2)
    assert stale.prediction_stale and at - sent < 1.0 and r1.verdicts(2)[0] - sent < 1.0
    fresh2 = r2.report(2, fresh=True)[1]  # the same marking on robot2, predicted
    assert _entries(stale) == [e for e in _entries(fresh2) if e[3] in ("explicit", "forced")]
    assert all(v.holds for v in r1.verdicts(2)[1].properties)
    # Down for longer than the Zenoh lease (10 s): both ends have dropped the link.
    wait_until(lambda: not r1.tokens.of("predictor"), 20, "robot1: the pool's tokens gone after the lease")
    time.sleep(max(0.0, 12 - (time.monotonic() - cut)))
    assert r1.report(2, fresh=True) is None, "no prediction reached robot1 during the cut"

    _docker("network", "connect", "--alias", "robot1", net, r1.router())
    back = time.monotonic()
    wait_until(lambda: r1.report(2, fresh=True) is not None, 10, "robot1: fresh again after reconnection")
    recovered = r1.report(2, fresh=True)[0] - back
    print(f"robot1 predictions fresh {recovered:.2f} s after its link came back")
    assert recovered < 2.0, recovered
    assert _entries(r1.report(2, fresh=True)[1]) == _entries(fresh2)


def test_whole_pool_down_marks_predictions_stale_then_recovers(fleet) -> None:
    hub, _, robots = fleet
    r2 = robots["robot2"]
    if r2.report(1) is None:  # run alone (or first): one step so that its report's seq is known
        wait_until(lambda: len(r2.tokens.of("predictor")) == 2 and r2.tokens.of("monitor"), 120, "robot2 up")
        r2.send("spot", "init_power.start")
        wait_until(lambda: r2.report(1, fresh=True) is not None, 60, "robot2: fresh step 1")
    hub.compose("stop", "-t", "5", "pool", timeout=60)
    wait_until(lambda: not r2.tokens.of("predictor"), 15, "robot2: no predictor left")
    step = max(m.seq for _, m in list(r2.items) if isinstance(m, UnsafeReport)) + 1
    sent = r2.send("manipulator", "arm_ready.start")
    wait_until(lambda: r2.report(step) is not None, 5, "robot2: the step with no pool")
    at, report = r2.report(step)
    assert report.prediction_stale and at - sent < 1.0
    hub.compose("start", "pool", timeout=60)
    wait_until(lambda: r2.report(step, fresh=True) is not None, 60, "robot2: fresh once the pool is back")


def test_twin_system_name_is_refused_with_one_line(fleet) -> None:
    _, net, robots = fleet
    twin = robots["robot3"]
    _docker("network", "connect", "--alias", "robot3", net, twin.router())
    wait_until(lambda: len(twin.tokens.of("predictor")) == 2, 60, "robot3: linked to the hub")
    twin.stack.compose("up", "-d", "--no-build", "monitor", timeout=120)
    (monitor,) = twin.stack.containers("monitor", running=False)

    def lines() -> list[str]:
        logs = subprocess.run(["docker", "logs", monitor], capture_output=True, text=True)
        return [line for line in (logs.stdout + logs.stderr).splitlines() if line.strip()]

    wait_until(lambda: bool(lines()), 60, "the twin monitor's error")
    # robot1's monitor, seen through the hub, refuses the twin: one line per (re)start.
    assert all(re.fullmatch(TWIN_ERROR.format("[0-9a-f]{8}"), line) for line in lines()), lines()
    code = subprocess.run(["docker", "inspect", "-f", "{{.State.ExitCode}}", monitor], capture_output=True,
                          text=True, check=True).stdout.strip()
    assert code in ("0", "1"), code  # exited 1 (or being restarted by the restart policy)


def test_monitor_with_a_wrong_router_endpoint_exits_with_one_line(image: str) -> None:
    t0 = time.monotonic()
    r = subprocess.run(["docker", "run", "--rm", "-e", "SKINET_ZENOH_CONNECT=tcp/127.0.0.1:9",
                        "-e", "SKINET_ZENOH_CONNECT_TIMEOUT=2", image, "monitor", "skillsets/spot_arm.toml"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stdout == "", (r.stdout, r.stderr)
    assert r.stderr.splitlines() == [  # after SKINET_ZENOH_CONNECT_TIMEOUT
        "python -m services.monitor: error: cannot open the Zenoh session: nothing answers at tcp/127.0.0.1:9"]
    assert time.monotonic() - t0 < 30


def test_hub_with_a_plain_tcp_robot_endpoint_exits_with_one_line(image: str) -> None:
    t0 = time.monotonic()
    r = subprocess.run(["docker", "run", "--rm", "-e", "SKINET_FLEET_ROBOTS=tls/robot1:7447,tcp/robot2:7447",
                        image, "router", "--listen", "tls/0.0.0.0:7447"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stdout == "", (r.stdout, r.stderr)
    assert r.stderr.splitlines() == [
        "skinet: error: robot endpoint 'tcp/robot2:7447' must be tls/HOST:PORT (a robot's router accepts TLS only)"]
    assert time.monotonic() - t0 < 30

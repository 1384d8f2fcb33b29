"""The compose stack (docs/semantics.md §7): router, bridge, monitor, two predictors, simulator.

The image is built with ``docker/build.sh --local-base`` (a Debian base made with
debootstrap, so no registry is needed; Docker's cache makes later runs quick).  The
stack runs under a project name of its own with the router published on a free
port of 127.0.0.1, where an observer logs in from the host as the ``observer`` user.
The tests share one stack and run in order: mission, predictor replacement,
off-board network cut, router restart.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from services.common.events import event_publisher
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CanonicalEvent, LiveState
from deploy_support import (
    REPO, MissionObserver, Tokens, answering_predictor, expected_violations, free_port, load_scenario, wait_until,
)

pytestmark = pytest.mark.slow

IMAGE = os.environ.get("SKINET_TEST_IMAGE", "skinet-live:local")  # own tag per checkout under test
SECRETS_IN_IMAGE = "/var/lib/skinet/secrets"  # each service's own files (the job's vault, in its container)
HANDED_IN_IMAGE = "/var/lib/skinet/handed"  # the router's hand-out, read-only (compose.yaml)
USER_SERVICE = {"bridge": "bridge", "monitor": "monitor", "predictor": "predictor", "robot": "simulator",
                "observer": "dashboard", "pilot": "pilot"}  # the compose service holding each user's files
BUILD_TIMEOUT = 2400  # a first build (debootstrap, wheels, image) took 20 min on a loaded 2-core machine


def _docker_engine() -> str | None:
    """None when a Docker engine answers, else why not."""
    if shutil.which("docker") is None:
        return "no docker command"
    try:
        r = subprocess.run(["docker", "info", "--format", "{{.ServerVersion}}"], capture_output=True, text=True,
                           timeout=30)
    except subprocess.TimeoutExpired:
        return "docker info timed out"
    return None if r.returncode == 0 else f"docker info failed: {(r.stderr or r.stdout).strip()[:200]}"


_NO_ENGINE = _docker_engine()
if _NO_ENGINE:
    pytest.skip(f"no Docker engine on this machine ({_NO_ENGINE}); the container tests need one",
                allow_module_level=True)


def _compose_command() -> list[str]:
    """``docker compose`` (v2 plugin) or ``docker-compose`` (v1, Debian's package)."""
    if subprocess.run(["docker", "compose", "version"], capture_output=True).returncode == 0:
        return ["docker", "compose"]
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    pytest.fail("a Docker engine is here but neither `docker compose` nor `docker-compose` is installed")


class Stack:
    """One compose project of ``compose.yaml``, driven through the compose command line."""

    def __init__(self, project: str, env: dict[str, str]):
        self.project, self.env = project, env
        self.command = _compose_command() + ["-f", str(REPO / "compose.yaml"), "-p", project]

    def compose(self, *args: str, timeout: float = 120, check: bool = True, input: str | None = None,
                **env: str) -> subprocess.CompletedProcess:
        r = subprocess.run([*self.command, *args], cwd=REPO, env={**self.env, **env}, capture_output=True,
                           text=True, timeout=timeout, input=input)
        if check and r.returncode != 0:
            raise AssertionError(f"compose {' '.join(args)} failed ({r.returncode}):\n{r.stdout}\n{r.stderr}")
        return r

    def start_compose(self, *args: str, **env: str) -> subprocess.Popen:
        return subprocess.Popen([*self.command, *args], cwd=REPO, env={**self.env, **env},
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def containers(self, service: str, running: bool = True) -> list[str]:
        """Names of the project's containers of ``service`` (compose v1 and v2 alike, by label)."""
        args = ["docker", "ps", "--format", "{{.Names}}", "--filter", f"label=com.docker.compose.project={self.project}",
                "--filter", f"label=com.docker.compose.service={service}"]
        if not running:
            args.append("--all")
        return sorted(subprocess.run(args, capture_output=True, text=True, check=True).stdout.split())

    def network(self, name: str) -> str:
        out = subprocess.run(["docker", "network", "ls", "--format", "{{.Name}}",
                              "--filter", f"label=com.docker.compose.project={self.project}",
                              "--filter", f"label=com.docker.compose.network={name}"],
                             capture_output=True, text=True, check=True).stdout.split()
        assert len(out) == 1, f"network {name} of {self.project}: {out}"
        return out[0]

    def run_simulator(self, speed: float) -> subprocess.Popen:
        """The demo's simulator as a one-off container (plays the unassisted mission once)."""
        return self.start_compose("run", "-T", "--rm", "--no-deps", "simulator",
                                  SKINET_SPEED=str(speed), SKINET_START_DELAY="0")

    def credentials(self, user: str, folder: Path) -> Path:
        """``user``'s own files, copied out of the container of the service that uses them into
        ``folder/<user>`` as docs/deployment.md ("Host access") does it: a shell pipeline from
        ``compose run`` of that service (``exec`` when it runs: each compose command costs
        about a second, compose v1 being a Python program)."""
        service = USER_SERVICE[user]
        target = folder / user
        target.mkdir(parents=True, exist_ok=True)
        how = ["exec", "-T"] if self.containers(service) else ["run", "--rm", "--no-deps", "-T"]
        compose = " ".join(shlex.quote(a) for a in self.command)
        r = subprocess.run(f"{compose} {' '.join(how)} {service} tar -C {SECRETS_IN_IMAGE} -c . "
                           f"| tar -x --no-same-owner -C {shlex.quote(str(target))}", shell=True, cwd=REPO,
                           env=self.env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and (target / f"{user}.password").exists(), r
        return target

    def client_config(self, user: str, folder: Path, endpoint: str) -> Path:
        """``skinet client-config`` on the host for ``user``'s files (:meth:`credentials`)."""
        secrets = self.credentials(user, folder)
        output = folder / f"{user}.json5"
        r = subprocess.run([sys.executable, "-m", "skinet_cli.main", "client-config", "--secrets", str(secrets),
                            "--user", user, "--connect", endpoint, "-o", str(output)], cwd=REPO, capture_output=True,
                           text=True, timeout=60)
        assert r.returncode == 0, r
        return output

    def logs(self) -> str:
        r = self.compose("logs", "--no-color", "--tail", "300", check=False, timeout=60)
        return r.stdout + r.stderr

    def down(self) -> None:
        self.compose("down", "-v", "-t", "2", "--remove-orphans", check=False, timeout=120)
        left = subprocess.run(["docker", "ps", "-aq", "--filter", f"label=com.docker.compose.project={self.project}"],
                              capture_output=True, text=True).stdout.split()
        if left:  # one-off containers of `compose run -d`
            subprocess.run(["docker", "rm", "-f", *left], capture_output=True)
            self.compose("down", "-v", "-t", "2", check=False, timeout=120)


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> str:
    """``skinet-live:local`` on the debootstrapped base, rebuilt only where sources changed."""
    log = tmp_path_factory.mktemp("build") / "build.log"
    with log.open("w") as out:
        r = subprocess.run(["bash", str(REPO / "docker" / "build.sh"), "--local-base", "--tag", IMAGE], cwd=REPO,
                           env={**os.environ, "PYTHON": sys.executable}, stdout=out, stderr=subprocess.STDOUT,
                           timeout=BUILD_TIMEOUT)
    if r.returncode != 0:
        pytest.fail(f"docker/build.sh failed ({r.returncode}); last lines of {log}:\n"
                    + "\n".join(log.read_text(errors="replace").splitlines()[-40:]))
    return IMAGE


@pytest.fixture(scope="module")
def stack(image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Stack, str]]:
    """The demo profile without its simulator; yields the stack and the router's host endpoint."""
    port = free_port()
    env = {**os.environ, "COMPOSE_PROFILES": "demo", "SKINET_IMAGE": image,
           "SKINET_ROUTER_PORT": f"127.0.0.1:{port}", "SKINET_PREDICTORS": "2", "SKINET_LOG_LEVEL": "INFO"}
    s = Stack(f"skinet-test-{os.getpid()}", env)
    try:
        s.compose("up", "-d", "--no-build", "router", "bridge", "monitor", "predictor", timeout=180)
        yield s, f"tls/127.0.0.1:{port}"
    finally:
        log = tmp_path_factory.mktemp("compose") / "compose.log"
        log.write_text(s.logs())
        print(f"compose logs: {log}")
        s.down()


@pytest.fixture(scope="module")
def secrets(stack: tuple[Stack, str], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The host's Zenoh configurations of observer, monitor and bridge (``skinet client-config``
    on each user's files, copied out of its service's container)."""
    folder = tmp_path_factory.mktemp("secrets")
    for user in ("observer", "monitor", "bridge"):
        stack[0].client_config(user, folder, stack[1])
    return folder


def host_login(stack: tuple[Stack, str], secrets: Path, user: str) -> zenoh.Session:
    """A host session of ``user`` with the configuration ``skinet client-config`` wrote."""
    config = zenoh.Config.from_file(str(secrets / f"{user}.json5"))
    config.insert_json5("connect/timeout_ms", "30000")  # the router may still be starting
    return zenoh.open(config)


@pytest.fixture(scope="module")
def observer(stack: tuple[Stack, str], secrets: Path) -> Iterator[zenoh.Session]:
    """The host's observer session, once every service has announced itself."""
    session = host_login(stack, secrets, "observer")
    tokens = Tokens(session)
    try:
        wait_until(lambda: tokens.of("bridge_ros2") and tokens.of("monitor") and len(tokens.of("predictor")) >= 2,
                   90, f"the services' liveliness tokens (got {sorted(tokens.alive)})")
        yield session
    finally:
        tokens.close()
        session.close()


def _restart_monitor(s: Stack, observer: zenoh.Session) -> None:
    """A monitor with an empty prediction cache: the next markings need the predictors.

    (It keeps predictions per marking, so a second run of the mission would otherwise be
    answered from its cache without any predictor.)
    """
    tokens = Tokens(observer)
    try:
        (monitor,) = s.containers("monitor")
        restarted_at = time.monotonic()
        subprocess.run(["docker", "restart", "-t", "2", monitor], check=True, capture_output=True)
        wait_until(lambda: tokens.of("monitor", restarted_at), 60, "the restarted monitor")
    finally:
        tokens.close()


def _container_of(instance: str) -> str:
    """A predictor's container from its instance id (``<hostname>-<pid>``; the hostname is the
    container id's prefix)."""
    hostname = instance.rsplit("-", 1)[0]
    out = subprocess.run(["docker", "ps", "-q", "--no-trunc", "--filter", f"id={hostname}"], capture_output=True,
                         text=True, check=True).stdout.split()
    assert len(out) == 1, f"no single container for instance {instance}: {out}"
    return out[0]


def _finish(sim: subprocess.Popen, timeout: float = 120) -> None:
    out, _ = sim.communicate(timeout=timeout)
    assert sim.returncode == 0, f"simulator exited {sim.returncode}:\n{out}"


def _settle(obs: MissionObserver) -> None:
    wait_until(lambda: obs.quiet_for(1.5), 30, "the monitor to settle")


# Every file under /var/lib/skinet and every ca.key anywhere (but /proc, /sys, /dev), with mode and owner.
FILES = """
import os
for root, dirs, files in os.walk('/'):
    if root == '/':
        dirs[:] = [d for d in dirs if d not in ('proc', 'sys', 'dev')]
    for f in files:
        p = os.path.join(root, f)
        if p.startswith('/var/lib/skinet/') or f == 'ca.key':
            st = os.lstat(p)
            print(p, oct(st.st_mode & 0o777), st.st_uid)
"""


def _own_files(user: str) -> set[str]:
    """The router also sees the job's hand-out, read-only, of which its own folder holds a copy (issue 31)."""
    names = ({"users.txt": "600", "tls/router.pem": "644", "tls/router.key": "600"} if user == "router" else
             {f"{user}.password": "600", f"tls/{user}.pem": "644", f"tls/{user}.key": "600"})
    folders = [SECRETS_IN_IMAGE, HANDED_IN_IMAGE] if user == "router" else [SECRETS_IN_IMAGE]
    return {f"{f}/{n} 0o{m} 10001" for f in folders for n, m in {**names, "tls/ca.pem": "644"}.items()}


def test_each_service_holds_only_its_own_credentials(stack: tuple[Stack, str], observer: zenoh.Session) -> None:
    """Issue 25 item 7: a volume per service with its own password, certificate and key (0600
    for secrets), the CA key in the vault alone, which only the one-shot job mounts."""
    s = stack[0]
    for service, user in [("router", "router"), *((svc, u) for u, svc in USER_SERVICE.items())]:
        running = s.containers(service)
        if running:
            listings = [subprocess.run(["docker", "exec", c, "python3", "-c", FILES], capture_output=True, text=True,
                                       check=True, timeout=60).stdout for c in running]
        else:
            listings = [s.compose("run", "--rm", "--no-deps", "-T", service, "python3", "-c", FILES).stdout]
        for listing in listings:
            assert set(listing.splitlines()) == _own_files(user), (service, listing)
    vault = f"{s.project}_secrets"
    mounted = set()
    for container in s.containers("secrets", running=False) + [c for svc in ("router", *USER_SERVICE)
                                                                for c in s.containers(svc, running=False)]:
        info = json.loads(subprocess.run(["docker", "inspect", container], capture_output=True, text=True,
                                         check=True).stdout)[0]
        if any(m.get("Name") == vault for m in info["Mounts"]):
            mounted.add((info["Config"]["Labels"]["com.docker.compose.service"], info["HostConfig"]["NetworkMode"],
                         info["State"]["Status"], info["State"]["ExitCode"]))
    assert mounted == {("secrets", "none", "exited", 0)}
    # What the job writes into is read-only wherever else it is mounted: no service can plant a link there.
    handed = {f"{s.project}_{user}-secrets" for user in ("router", *USER_SERVICE)}
    writable = set()
    for container in [c for svc in ("router", *USER_SERVICE.values()) for c in s.containers(svc, running=False)]:
        info = json.loads(subprocess.run(["docker", "inspect", container], capture_output=True, text=True,
                                         check=True).stdout)[0]
        writable |= {(info["Config"]["Labels"]["com.docker.compose.service"], m["Name"]) for m in info["Mounts"]
                     if m.get("Name") in handed and m.get("RW")}
    assert writable == set()


def test_unassisted_mission_gives_the_in_process_verdicts(stack: tuple[Stack, str], observer: zenoh.Session) -> None:
    obs = MissionObserver(observer)
    try:
        _finish(stack[0].run_simulator(speed=10))
        _settle(obs)
        assert obs.violations(load_scenario()) == expected_violations(), obs.event_trace()
        assert any(not r.prediction_stale for _, r in obs.unsafe), "no prediction reached the monitor"
        assert obs.state_space, "no state-space report"
    finally:
        obs.close()


def test_predictor_replaced_while_events_flow(stack: tuple[Stack, str], observer: zenoh.Session,
                                             secrets: Path) -> None:
    s = stack[0]
    _restart_monitor(s, observer)
    obs, tokens = MissionObserver(observer), Tokens(observer)
    asker = host_login(stack, secrets, "monitor")  # observers may not query predictors
    try:
        wait_until(lambda: len(tokens.of("predictor")) >= 2, 30, "two predictors")
        before = tokens.of("predictor")
        victim = _container_of(answering_predictor(asker))  # the one serving the monitor
        sim = s.run_simulator(speed=5)
        wait_until(lambda: obs.count() >= 10, 60, "events flowing")
        killed_at = time.monotonic()
        subprocess.run(["docker", "kill", victim], check=True, capture_output=True)
        wait_until(lambda: len(tokens.of("predictor")) == len(before) - 1, 15, "the killed predictor's token to go")
        s.compose("run", "-d", "--no-deps", "predictor")
        wait_until(lambda: len(tokens.of("predictor")) == len(before), 60, "the new predictor's token")
        assert tokens.of("predictor") - before, "no new predictor instance"
        _finish(sim)
        _settle(obs)

        late = {e: d for e, d in obs.verdict_delays().items() if d > 0.5}
        assert not late, f"verdicts later than 0.5 s after their event: {late}"
        after = obs.fresh_delays(since=killed_at)
        assert len(after) >= 10, f"too few events after the kill: {after}"
        slow = {seq: d for seq, d in after.items() if d is None or d > 1.0}
        assert not slow, f"states without a fresh prediction within 1 s after the kill: {slow} (all: {after})"
    finally:
        asker.close()
        obs.close()
        tokens.close()


def test_offboard_network_cut_leaves_stale_predictions_then_recovers(stack: tuple[Stack, str],
                                                                   observer: zenoh.Session) -> None:
    """Markings predicted before the cut stay predicted (the monitor keeps predictions per
    marking); new ones stay stale until the predictors are back."""
    s = stack[0]
    _restart_monitor(s, observer)
    network = s.network("offboard")
    predictors = s.containers("predictor")
    obs = MissionObserver(observer)
    sim = s.run_simulator(speed=5)
    cut = False
    try:
        wait_until(lambda: obs.count() >= 5, 60, "events flowing")
        for c in predictors:
            subprocess.run(["docker", "network", "disconnect", network, c], check=True, capture_output=True)
        cut, cut_at = True, time.monotonic()
        wait_until(lambda: obs.count() >= 30, 60, "events during the cut")
        back_at = time.monotonic()
        known = {obs.marking(seq) for _, seq in obs.fresh(end=cut_at)}
        new = [seq for seq in obs.states_between(cut_at + 0.5, back_at) if obs.marking(seq) not in known]
        assert new, "no new marking during the cut"
        fresh_new = sorted({seq for _, seq in obs.fresh(cut_at + 0.5, back_at)} & set(new))
        assert not fresh_new, f"fresh predictions of new markings while the predictors were cut off: {fresh_new}"
        late = {e: d for e, d in obs.verdict_delays().items() if d > 0.5}
        assert not late, f"verdicts later than 0.5 s after their event: {late}"

        for c in predictors:
            subprocess.run(["docker", "network", "connect", network, c], check=True, capture_output=True)
        cut = False
        # The predictors' sessions come back (lease expiry, then reconnection) and the
        # monitor asks again: a marking never predicted before gets its prediction.
        known = {obs.marking(seq) for _, seq in obs.fresh(end=back_at)}
        wait_until(lambda: any(obs.marking(seq) not in known for _, seq in obs.fresh(back_at)), 60,
                   "a fresh prediction of a new marking after reconnecting")
        _finish(sim)
        _settle(obs)
    finally:
        if cut:
            for c in predictors:
                subprocess.run(["docker", "network", "connect", network, c], capture_output=True)
        if sim.poll() is None:
            sim.wait(timeout=120)
        obs.close()


def _latest_state(session: zenoh.Session) -> LiveState | None:
    """The monitor's last published state, as a late joiner asks for it (None: no answer yet)."""
    for reply in session.get(keys.state("spot_arm"), timeout=2.0):
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes(), LiveState)
    return None


def _sync_reason(st: LiveState | None, skillset: str) -> str:
    """Why the monitor cannot vouch for ``skillset`` in ``st`` ('' when it can, or without a state)."""
    return st.sync[skillset].reason if st is not None and skillset in st.sync else ""


def _all_in(st: LiveState | None, *states: str) -> bool:
    """Whether every skillset of ``st`` is in one of the sync states ``states`` (live, syncing, lost)."""
    return st is not None and bool(st.sync) and all(s.state in states for s in st.sync.values())


def _standby_robot(s: Stack) -> str:
    """The simulator serving spot_arm's managers without playing anything (a start delay of an
    hour): a robot at rest, which answers the bridge's status requests.  Returns its container."""
    before = set(s.containers("simulator"))
    s.compose("run", "-d", "--no-deps", "simulator", SKINET_START_DELAY="3600")
    (robot,) = set(s.containers("simulator")) - before
    return robot


def test_router_restart_clients_reconnect(stack: tuple[Stack, str], observer: zenoh.Session) -> None:
    """Every service comes back after ``docker restart`` of the router, and the next mission gives
    the in-process verdicts.

    No robot runs across the restart: the bridge cannot tell what its managers did while its
    link was cut, so the monitor vouches for no skillset (docs/semantics.md §7) until the mission's
    managers answer the bridge; it then publishes its last step again with the new sync state,
    which is no step of the mission (:class:`MissionObserver`'s ``after``).  Unvouched is syncing
    (the bridge came back) or lost (the managers answered none of its requests): syncing lasts
    until the bridge's next heartbeat, or its third unanswered poll, so a wait for it alone
    could miss it (a CI run of session 18's found every skillset lost already)."""
    s = stack[0]
    tokens = Tokens(observer)
    try:
        (router,) = s.containers("router")
        restarted_at = time.monotonic()
        subprocess.run(["docker", "restart", "-t", "1", router], check=True, capture_output=True)
        # Each service announces itself anew through the new router.
        wait_until(lambda: (tokens.of("bridge_ros2", restarted_at) and tokens.of("monitor", restarted_at)
                            and len(tokens.of("predictor", restarted_at)) >= 2),
                   60, f"every service back (got {sorted(tokens.alive)})")
    finally:
        tokens.close()
    latest: list[LiveState | None] = [None]

    def unvouched() -> bool:
        latest[0] = _latest_state(observer)
        return _all_in(latest[0], "syncing", "lost")

    try:
        wait_until(unvouched, 30, "spot and manipulator syncing or lost after the restart")
    except AssertionError as exc:  # say what the monitor showed instead (a run of session 15 timed out here)
        shown = {k: (v.state, v.reason) for k, v in latest[0].sync.items()} if latest[0] is not None else None
        raise AssertionError(f"{exc}; the monitor's last state shows {shown}") from None
    assert latest[0] is not None
    obs = MissionObserver(observer, after=latest[0].seq)  # no step can come before the mission's managers answer
    try:
        _finish(s.run_simulator(speed=10))
        _settle(obs)
        assert obs.violations(load_scenario()) == expected_violations(), (obs.events(), obs.event_trace())
        assert any(not r.prediction_stale for _, r in obs.unsafe)
    finally:
        obs.close()


def test_router_restart_loses_no_event(stack: tuple[Stack, str], observer: zenoh.Session, secrets: Path) -> None:
    """Events published while the router restarts reach the monitor, in order: none lost.

    The host publishes status events of its own stream as the bridge does (advanced
    publisher: cache and heartbeats) before, during and after ``docker restart`` of
    the router; the monitor (advanced subscriber) applies each once, so its step
    counter grows by exactly the number of events (plus the resync steps), and it
    logs no gap for the stream.

    The restart also cut the stack's bridge from spot's manager: until the manager's
    next status closes that gap the bridge refuses the resync, and the monitor does
    not vouch for spot (docs/semantics.md §7): the host's events wait.  So a robot at rest serves
    the managers (a simulator that plays nothing), frozen (``docker pause``) across
    the restart so that the refusal is seen, then thawed to answer.
    """
    s = stack[0]
    states: list[LiveState] = []
    sub = observer.declare_subscriber(keys.state("spot_arm"), lambda x: states.append(
        decode(x.payload.to_bytes(), LiveState)))
    robot = _standby_robot(s)
    paused = False
    bridge = host_login(stack, secrets, "bridge")
    publisher = event_publisher(bridge, keys.events("spot_arm", "spot"))
    source, sent = f"host-{os.getpid()}", 0
    transitions = ("init_power.start", "init_power.success.powered_on")

    def name(n: int) -> str:
        return f"spot:{transitions[n % 2]}#{n}"

    def publish(n: int, rate: float = 40.0) -> None:
        nonlocal sent
        for _ in range(n):
            # Named transitions: each is a step of the monitor (a status confirming the marking is not).
            ev = CanonicalEvent(system="spot_arm", skillset="spot", seq=sent, stamp=time.time(), source=source,
                                transition=transitions[sent % 2])
            publisher.put(encode(ev))
            sent += 1
            time.sleep(1 / rate)

    try:
        # The bridge has a status of each skillset (from the robot at rest, or an earlier mission).
        wait_until(lambda: _all_in(_latest_state(observer), "live"), 60, "spot and manipulator live")
        publish(10)
        wait_until(lambda: any(st.event == name(sent - 1) for st in states), 30, "the first events")
        first = max(st.seq for st in states)
        subprocess.run(["docker", "pause", robot], check=True, capture_output=True)
        paused = True
        (router,) = s.containers("router")
        restart = threading.Thread(target=subprocess.run, args=(["docker", "restart", "-t", "1", router],),
                                   kwargs={"check": True, "capture_output": True})
        restart.start()
        publish(160)  # 4 s: the router is down for part of it
        restart.join()
        publish(10)
        # The bridge's words: the cut link, or (its polls of the paused robot unanswered) the silent manager.
        why = re.compile(r"has no current status of spot: (the link to the managers was cut|manager "
                         r"/spot/spot_skillset_manager answered none of the last \d+ status requests)")
        wait_until(lambda: bool(why.search(_sync_reason(_latest_state(observer), "spot"))), 60,
                   "the monitor to say why it cannot vouch for spot")
        assert not any(st.event == name(sent - 1) for st in states), "an event applied while spot was not live"
        subprocess.run(["docker", "unpause", robot], check=True, capture_output=True)
        paused = False
        wait_until(lambda: any(st.event == name(sent - 1) for st in states), 60,
                   "the last event after the restart")
        steps = {st.seq: st.event for st in states if st.seq > first}
        last = max(steps)
        ours = {name(n) for n in range(sent)}
        host = [e for _, e in sorted(steps.items()) if e in ours]
        others = [e for e in steps.values() if e not in ours]
        # The observer was back before the robot thawed, so it saw every step that is not the host's.
        assert all(re.fullmatch(r"(spot|manipulator):(status|resync)#\d+", e) for e in others), others
        assert last - first - len(others) == sent - 10, \
            f"{sent - 10} events and {len(others)} other steps ({others}) after step {first}, but the monitor " \
            f"reached {last}"
        numbers = [int(e.rsplit("#", 1)[1]) for e in host]
        assert numbers == sorted(set(numbers)), f"host events out of order or twice: {numbers}"
        logs = s.compose("logs", "--no-color", "monitor", check=False).stdout
        # No gap, duplicate, reordering or lost stretch of the host's stream.  Its sync state may change (the
        # restart can outlast --lost-after: "events from '<source>' again: waiting for its resync answer").
        problems = re.compile(r"lost events|duplicate event|out-of-order event|sequence (jump|restarted)|did not come|new run")
        assert [line for line in logs.splitlines() if source in line and problems.search(line)] == []
    finally:
        if paused:
            subprocess.run(["docker", "unpause", robot], capture_output=True)
        subprocess.run(["docker", "rm", "-f", robot], capture_output=True)
        publisher.undeclare()
        bridge.close()
        sub.undeclare()

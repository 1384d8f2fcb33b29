"""Several robots and one off-board router with a shared predictor pool, through the
shipped access control (docs/semantics.md §7), without containers: routers are Python sessions.

Each robot's router runs ``docker/zenoh/router.json5``; the off-board router runs
``docker/zenoh/hub.json5`` and connects to both robots as the user ``hub``;
predictors are clients of the off-board router, monitors clients of their robot's
router, all separate processes logged in as their users.
(``test_fleet.py`` runs the same topology in containers on separate Docker networks
and cuts links.)
"""

from __future__ import annotations

import json
import shutil
import socket
import threading
import time
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import (
    REPO, USERS_FILE, ZENOH_DIR, Services, Tokens, acl_router_config, free_port, login, passwords, wait_until,
)
from skinet.wire import keys
from skinet.system.load import load_system
from skinet.wire.codec import decode
from skinet.wire.messages import UnsafeReport
from tests.services.test_monitor import Events


class FreezableLink:
    """A TCP relay to ``port`` whose traffic can be held (a link cut silently, as a pulled
    cable: both ends keep their sockets) and later dropped, after which it relays new
    connections again."""

    def __init__(self, port: int):
        self.target = ("127.0.0.1", port)
        self._server = socket.create_server(("127.0.0.1", 0))
        self.endpoint = f"tcp/127.0.0.1:{self._server.getsockname()[1]}"
        self._cut = threading.Event()
        self._open: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._server.accept()
            except OSError:
                return
            if self._cut.is_set():
                conn.close()
                continue
            upstream = socket.create_connection(self.target)
            self._open += [conn, upstream]
            for a, b in ((conn, upstream), (upstream, conn)):
                threading.Thread(target=self._relay, args=(a, b), daemon=True).start()

    def _relay(self, a: socket.socket, b: socket.socket) -> None:
        try:
            while data := a.recv(65536):
                while self._cut.is_set():  # hold the bytes: the senders' buffers fill up
                    time.sleep(0.05)
                    if a.fileno() < 0:
                        return
                b.sendall(data)
        except OSError:
            return

    def cut(self) -> None:
        self._cut.set()

    def restore(self) -> None:
        """Close the held connections (both ends gave up on them after the lease) and relay again."""
        for s in self._open:
            s.close()
        self._open = []
        self._cut.clear()

    def close(self) -> None:
        self._server.close()
        self.restore()


def fleet_skillsets(folder: Path, *names: str) -> Path:
    """``skillsets/`` plus one system file per robot: the paper's robot under another name."""
    shutil.copytree(REPO / "skillsets", folder, dirs_exist_ok=True)
    text = (REPO / "skillsets" / "spot_arm.toml").read_text()
    for name in names:
        (folder / f"{name}.toml").write_text(text.replace('name = "spot_arm"', f'name = "{name}"'))
    return folder


def hub_config(listen: str, robots: list[str]) -> zenoh.Config:
    """``docker/zenoh/hub.json5`` with the repository's users, logging in to ``robots`` as ``hub``."""
    config = zenoh.Config.from_file(str(ZENOH_DIR / "hub.json5"))
    config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(str(USERS_FILE)))
    config.insert_json5("transport/auth/usrpwd/user", '"hub"')
    config.insert_json5("transport/auth/usrpwd/password", json.dumps(passwords()["hub"]))
    config.insert_json5("listen/endpoints", json.dumps([listen]))
    config.insert_json5("connect/endpoints", json.dumps(robots))
    config.insert_json5("scouting/delay", "0")
    return config


class Fleet(Services):
    """Routers (in this process) and service processes (logged in as their users)."""

    def __init__(self, tmp_path: Path):
        super().__init__(tmp_path)
        ports = {r: free_port() for r in ("robot1", "robot2")}
        self.robots = {r: f"tcp/127.0.0.1:{p}" for r, p in ports.items()}
        self.hub = f"tcp/127.0.0.1:{free_port()}"
        self.skillsets = fleet_skillsets(tmp_path / "skillsets", "robot1", "robot2")
        self.routers = [zenoh.open(acl_router_config(e)) for e in self.robots.values()]
        self.links = {r: FreezableLink(p) for r, p in ports.items()}  # the hub reaches each robot through one
        self.routers.append(zenoh.open(hub_config(self.hub, [link.endpoint for link in self.links.values()])))

    def monitor(self, robot: str, system: str | None = None) -> subprocess.Popen:
        return self.start("services.monitor", "monitor", self.robots[robot],
                          str(self.skillsets / f"{system or robot}.toml"), "--id", f"{robot}-monitor")

    def close(self) -> None:
        super().close()
        for r in reversed(self.routers):
            r.close()
        for link in self.links.values():
            link.close()


@pytest.fixture
def fleet(tmp_path: Path) -> Iterator[Fleet]:
    f = Fleet(tmp_path)
    yield f
    f.close()


class Reports:
    """UnsafeReports of one system, as an observer on one robot's router receives them."""

    def __init__(self, session: zenoh.Session, system: str):
        self.items: list[tuple[float, UnsafeReport]] = []  # (arrival, report)
        self._sub = session.declare_subscriber(keys.unsafe(system), lambda s: self.items.append(
            (time.monotonic(), decode(s.payload.to_bytes(), UnsafeReport))))

    def has(self, predicate: Callable[[UnsafeReport], bool]) -> bool:
        return self.first(predicate) is not None

    def first(self, predicate: Callable[[UnsafeReport], bool]) -> float | None:
        """Arrival time of the first report satisfying ``predicate``."""
        return next((t for t, r in list(self.items) if predicate(r)), None)


def robot_events(fleet: Fleet, session: zenoh.Session, robot: str) -> Events:
    """The bridge's side of one robot (events, heartbeats, resync answers), as the bridge user on its router."""
    return Events(session, robot, model=load_system(fleet.skillsets / f"{robot}.toml")[0], wait=False)


def test_two_robots_share_the_offboard_pool_and_a_twin_name_is_refused(fleet: Fleet) -> None:
    fleet.start("services.predictor", "predictor", fleet.hub, "--instance", "pool1")
    fleet.start("services.predictor", "predictor", fleet.hub, "--instance", "pool2")
    observers = {r: login(e, "observer") for r, e in fleet.robots.items()}
    bridge = login(fleet.robots["robot1"], "bridge")
    try:
        tokens = {r: Tokens(s) for r, s in observers.items()}
        reports = {r: Reports(observers[r], r) for r in fleet.robots}
        # The pool's tokens reach both robots through the hub link (the ACL's `hub` user).
        for r in fleet.robots:
            wait_until(lambda r=r: len(tokens[r].of("predictor")) == 2, 30, f"the pool's tokens on {r}")
        for r in fleet.robots:
            fleet.monitor(r)
        for r in fleet.robots:
            wait_until(lambda r=r: reports[r].has(lambda m: m.seq == 0 and not m.prediction_stale), 30,
                       f"a fresh prediction for {r}")
        # robot1 moves: its prediction of the new marking comes from the shared pool too.
        events = robot_events(fleet, bridge, "robot1")
        events.synced(30)
        events.send("manipulator", "arm_ready.start")
        wait_until(lambda: reports["robot1"].has(lambda m: m.seq == 1 and not m.prediction_stale), 15,
                   "robot1's fresh prediction after its event")
        assert not reports["robot2"].has(lambda m: m.seq == 1), "robot1's events stay on robot1"
        # A third monitor on robot2 under robot1's name sees robot1's monitor through the hub.
        twin = fleet.monitor("robot2", system="robot1")
        assert twin.wait(timeout=30) == 1
        assert fleet.log(twin).splitlines() == ["python -m services.monitor: error: system 'robot1' is already "
                                                "monitored by robot1-monitor on this Zenoh network: "
                       "give each robot its own system name ([system] name in its .toml)"]
    finally:
        for t in tokens.values():
            t.close()
        bridge.close()
        for s in observers.values():
            s.close()


def test_a_cut_robot_link_leaves_the_other_robot_fresh_and_recovers_within_2_s(fleet: Fleet) -> None:
    fleet.start("services.predictor", "predictor", fleet.hub, "--instance", "pool1")
    fleet.start("services.predictor", "predictor", fleet.hub, "--instance", "pool2")
    sessions = {r: (login(e, "observer"), login(e, "bridge")) for r, e in fleet.robots.items()}
    tokens = {r: Tokens(s[0]) for r, s in sessions.items()}
    try:
        reports = {r: Reports(s[0], r) for r, s in sessions.items()}
        events = {r: robot_events(fleet, s[1], r) for r, s in sessions.items()}
        for r in fleet.robots:
            wait_until(lambda r=r: len(tokens[r].of("predictor")) == 2, 30, f"the pool's tokens on {r}")
            fleet.monitor(r)
            wait_until(lambda r=r: tokens[r].of("monitor"), 30, f"{r}'s monitor")
        for r in fleet.robots:
            events[r].synced(30)
            events[r].send("spot", "init_power.start")
        for r in fleet.robots:
            wait_until(lambda r=r: reports[r].has(lambda m: m.seq == 1 and not m.prediction_stale), 30,
                       f"{r}: step 1 fresh")
        fleet.links["robot1"].cut()
        cut = time.monotonic()
        for step, transition in ((2, "init_power.success.powered_on"), (3, "stand_up.start")):
            for r in fleet.robots:
                sent = time.monotonic()
                events[r].send("spot", transition)
                wait_until(lambda r=r, s=step: reports[r].has(lambda m: m.seq == s), 2, f"{r}: step {step}")
                assert reports[r].first(lambda m, s=step: m.seq == s) - sent < 1.0, "verdicts on time"
            # robot2 is not affected; robot1 keeps its explicit constraints, predictions stale
            wait_until(lambda s=step: reports["robot2"].has(lambda m: m.seq == s and not m.prediction_stale), 5,
                       f"robot2: step {step} fresh during the cut")
            stale = next(m for _, m in reports["robot1"].items if m.seq == step)
            fresh = next(m for _, m in reports["robot2"].items if m.seq == step and not m.prediction_stale)
            assert stale.prediction_stale
            assert _entries(stale) == [e for e in _entries(fresh) if e[3] in ("explicit", "forced")]
        wait_until(lambda: not tokens["robot1"].of("predictor"), 20, "robot1: the pool gone after the lease")
        assert not reports["robot1"].has(lambda m: m.seq == 3 and not m.prediction_stale)
        time.sleep(max(0.0, 12 - (time.monotonic() - cut)))  # both ends have given up the link
        fleet.links["robot1"].restore()
        back = time.monotonic()
        wait_until(lambda: reports["robot1"].has(lambda m: m.seq == 3 and not m.prediction_stale), 10,
                   "robot1: step 3 fresh after the link came back")
        recovered = reports["robot1"].first(lambda m: m.seq == 3 and not m.prediction_stale) - back
        print(f"robot1 fresh {recovered:.2f} s after its link came back")
        assert recovered < 2.0, recovered
    finally:
        for t in tokens.values():
            t.close()
        for pair in sessions.values():
            for s in pair:
                s.close()


def _entries(report: UnsafeReport) -> list[tuple]:
    return sorted((e.skillset, e.transition, e.property, e.constraint) for e in report.unsafe)

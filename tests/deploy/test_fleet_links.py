"""Several robots and one off-board router with a shared predictor pool, through the
shipped access control (SPEC §7), without containers: routers are Python sessions.

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
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import (
    REPO, USERS_FILE, ZENOH_DIR, Services, Tokens, acl_router_config, free_port, login, passwords, wait_until,
)
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CanonicalEvent, UnsafeReport


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
        self.robots = {r: f"tcp/127.0.0.1:{free_port()}" for r in ("robot1", "robot2")}
        self.hub = f"tcp/127.0.0.1:{free_port()}"
        self.skillsets = fleet_skillsets(tmp_path / "skillsets", "robot1", "robot2")
        self.routers = [zenoh.open(acl_router_config(e)) for e in self.robots.values()]
        self.routers.append(zenoh.open(hub_config(self.hub, list(self.robots.values()))))

    def monitor(self, robot: str, system: str | None = None) -> subprocess.Popen:
        return self.start("services.monitor", "monitor", self.robots[robot],
                          str(self.skillsets / f"{system or robot}.toml"), "--id", f"{robot}-monitor")

    def close(self) -> None:
        super().close()
        for r in reversed(self.routers):
            r.close()


@pytest.fixture
def fleet(tmp_path: Path) -> Iterator[Fleet]:
    f = Fleet(tmp_path)
    yield f
    f.close()


class Reports:
    """UnsafeReports of one system, as an observer on one robot's router receives them."""

    def __init__(self, session: zenoh.Session, system: str):
        self.items: list[UnsafeReport] = []
        self._sub = session.declare_subscriber(keys.unsafe(system),
                                               lambda s: self.items.append(decode(s.payload.to_bytes(), UnsafeReport)))

    def has(self, predicate: Callable[[UnsafeReport], bool]) -> bool:
        return any(predicate(r) for r in list(self.items))


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
        event = CanonicalEvent(system="robot1", skillset="manipulator", seq=0, stamp=0.0, source="test",
                               transition="arm_ready.start")
        bridge.put(keys.events("robot1", "manipulator"), encode(event))
        wait_until(lambda: reports["robot1"].has(lambda m: m.seq == 1 and not m.prediction_stale), 15,
                   "robot1's fresh prediction after its event")
        assert not reports["robot2"].has(lambda m: m.seq == 1), "robot1's events stay on robot1"
        # A third monitor on robot2 under robot1's name sees robot1's monitor through the hub.
        twin = fleet.monitor("robot2", system="robot1")
        assert twin.wait(timeout=30) == 2
        assert fleet.log(twin).splitlines() == ["error: system 'robot1' is already monitored by robot1-monitor on this Zenoh network: "
                       "give each robot its own system name ([system] name in its .toml)"]
    finally:
        for t in tokens.values():
            t.close()
        bridge.close()
        for s in observers.values():
            s.close()

"""Shared Zenoh fixtures for service tests: a loopback router, clients, service processes.

Everything runs on 127.0.0.1 with multicast scouting off, so tests neither see nor
disturb other Zenoh traffic on the machine; sessions are clients of a router as in
a deployment (ZENOH.md).  Wait for liveliness tokens (:func:`watch`) rather than
sleeping.
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

# The service tests take these from here; each has one definition, for the benchmarks too.
from tests.loopback import client_args, free_endpoint, free_port, open_client, open_router  # noqa: F401
from tests.processes import REPO, start_module, start_skinet, stop_and_show  # noqa: F401


class LivelinessWatch:
    """The live tokens under a key expression, kept up to date, with a blocking wait."""

    def __init__(self, session: zenoh.Session, key_expr: str):
        self.alive: set[str] = set()
        self._cond = threading.Condition()
        self._sub = session.liveliness().declare_subscriber(key_expr, self._on_sample, history=True)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._cond:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(str(sample.key_expr))
            else:
                self.alive.discard(str(sample.key_expr))
            self._cond.notify_all()

    def wait(self, predicate: Callable[[set[str]], bool], timeout: float = 10.0) -> set[str]:
        """Block until ``predicate(alive)`` holds; fails the test after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not predicate(self.alive):
                left = deadline - time.monotonic()
                if left <= 0:
                    pytest.fail(f"liveliness condition not met within {timeout} s; alive: {sorted(self.alive)}")
                self._cond.wait(left)
            return set(self.alive)

    def wait_for(self, key: str, timeout: float = 10.0) -> None:
        self.wait(lambda alive: key in alive, timeout)

    def wait_gone(self, key: str, timeout: float = 10.0) -> None:
        self.wait(lambda alive: key not in alive, timeout)

    def close(self) -> None:
        self._sub.undeclare()


def wait_queryable(session: zenoh.Session, key: str, timeout: float = 10.0) -> None:
    """Until a queryable on ``key`` is reachable from ``session`` (one declared on another session reaches the
    router a moment later)."""
    querier = session.declare_querier(key)
    deadline = time.monotonic() + timeout
    try:
        while not querier.matching_status.matching:
            if time.monotonic() > deadline:
                pytest.fail(f"no queryable on {key} reachable within {timeout:g} s")
            time.sleep(0.005)
    finally:
        querier.undeclare()


@pytest.fixture
def router() -> Iterator[str]:
    """A fresh router (a Python session in router mode); yields ``tcp/127.0.0.1:PORT``."""
    endpoint = free_endpoint()
    session = open_router(endpoint)
    try:
        yield endpoint
    finally:
        session.close()


@pytest.fixture
def zenoh_args(router: str) -> list[str]:
    """:func:`client_args` for :func:`router`."""
    return client_args(router)


@pytest.fixture
def client_factory(router: str) -> Iterator[Callable[[], zenoh.Session]]:
    """Factory of client sessions connected to :func:`router`, closed after the test."""
    sessions: list[zenoh.Session] = []

    def open_() -> zenoh.Session:
        sessions.append(open_client(router))
        return sessions[-1]

    yield open_
    for session in reversed(sessions):
        session.close()


@pytest.fixture
def client(client_factory: Callable[[], zenoh.Session]) -> zenoh.Session:
    """A client session connected to :func:`router`."""
    return client_factory()


@pytest.fixture
def watch() -> Iterator[Callable[[zenoh.Session, str], LivelinessWatch]]:
    """Factory of :class:`LivelinessWatch` (``watch(session, key_expr)``)."""
    watches: list[LivelinessWatch] = []

    def make(session: zenoh.Session, key_expr: str) -> LivelinessWatch:
        w = LivelinessWatch(session, key_expr)
        watches.append(w)
        return w

    yield make
    for w in watches:
        try:
            w.close()
        except zenoh.ZError:
            pass  # its session is already closed


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., subprocess.Popen]]:
    """Factory starting ``python -m MODULE ARGS...`` from the repository root.

    Output goes to ``tmp_path/<module>-<n>.log`` (printed after the test, so a failure
    shows it); processes still running at the end get SIGTERM, then SIGKILL.
    """
    procs: list[tuple[subprocess.Popen, Path]] = []

    def start(module: str, *args: str) -> subprocess.Popen:
        log = tmp_path / f"{module}-{len(procs)}.log"
        procs.append((start_module(module, *args, log=log), log))
        return procs[-1][0]

    yield start
    stop_and_show(procs)


# -- the paper's system with its type map (simulator and bridge tests) ---------------------


@pytest.fixture(scope="session")
def spot_arm() -> tuple:
    """``skillsets/spot_arm.toml`` as the services load it: (system, type map)."""
    from skinet.system.load import load_system, load_typemap

    path = REPO / "skillsets" / "spot_arm.toml"
    return load_system(path)[0], load_typemap(path)


@pytest.fixture
def robots(client_factory: Callable[[], zenoh.Session], spot_arm: tuple) -> Iterator[Callable[..., Any]]:
    """Factory of the paper's robot with a pilot, each service on a client session of :func:`router`
    (:class:`tests.services.pilot_robot.Robot`; ``robots(**options)`` takes its options), closed after the test."""
    from tests.services.pilot_robot import Robot

    started: list[Robot] = []

    def start(**options: Any) -> Robot:
        started.append(Robot(client_factory, *spot_arm, **options))
        return started[-1]

    yield start
    for r in reversed(started):
        r.close()


@pytest.fixture
def robot(robots: Callable[..., Any]) -> Any:
    """:func:`robots` with the robot's defaults."""
    return robots()

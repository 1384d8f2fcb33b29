"""Shared Zenoh fixtures for service tests: a loopback router, clients, service processes.

Everything runs on 127.0.0.1 with multicast scouting off, so tests neither see nor
disturb other Zenoh traffic on the machine; sessions are clients of a router as in
a deployment (ZENOH.md).  Wait for liveliness tokens (:func:`watch`) rather than
sleeping.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from services.common.zenoh_config import session_config
from tests.processes import stop_and_show

REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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


def open_router(endpoint: str) -> zenoh.Session:
    """A Python session in router mode listening on ``endpoint``."""
    config = session_config("router", listen=[endpoint], multicast_scouting=False)
    config.insert_json5("scouting/delay", "0")  # nothing to scout: open at once, not after 0.5 s
    return zenoh.open(config)


def open_client(endpoint: str) -> zenoh.Session:
    """A client session connected to the router at ``endpoint``."""
    return zenoh.open(session_config("client", connect=[endpoint], multicast_scouting=False))


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


def start_skinet(*args: str) -> subprocess.Popen:
    """``skinet ARGS`` in its own process group, output (stderr too) on its text stdout."""
    return subprocess.Popen([sys.executable, "-m", "skinet_cli.main", *args], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


def client_args(endpoint: str) -> list[str]:
    """Command-line flags making a service a client of the router at ``endpoint``."""
    return ["--mode", "client", "--connect", endpoint, "--no-multicast-scouting"]


@pytest.fixture
def router() -> Iterator[str]:
    """A fresh router (a Python session in router mode); yields ``tcp/127.0.0.1:PORT``."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
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
        with log.open("wb") as out:
            proc = subprocess.Popen([sys.executable, "-m", module, *args], cwd=REPO,
                                    stdout=out, stderr=subprocess.STDOUT)
        procs.append((proc, log))
        return proc

    yield start
    stop_and_show(procs)


# -- the paper's system with its type map (simulator and bridge tests) ---------------------


@pytest.fixture(scope="session")
def spot_arm() -> tuple:
    """``skillsets/spot_arm.toml`` as the services load it: (system, type map)."""
    from skinet.system.load import load_system, load_typemap

    path = REPO / "skillsets" / "spot_arm.toml"
    return load_system(path)[0], load_typemap(path)

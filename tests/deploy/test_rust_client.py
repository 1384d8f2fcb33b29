"""``examples/rust_client`` against an embedded system behind the ACL router (slow: cargo build).

The client is built with the repository's cargo workspace (:mod:`native_build`).

Monitor and predictor run in this process, each on a client session logged in as
its user; the test plays the bridge's side (:class:`BridgeSide`: events, heartbeats,
resync answers) logged in as ``bridge``; the Rust client logs in as ``observer``,
asks the predictor and prints the verdicts of those events.  The client predates the
live-state fields of the messages (issue 25): serde ignores fields it does not know.
"""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy_support import REPO, SYSTEM, acl_router_config, free_port, login, passwords
from native_build import native_binary
from services.monitor import Monitor, start_monitor
from services.predictor import start_predictor
from skinet.system.load import load_system
from skinet.wire.messages import CheckRequest
from tests.bridge_side import BridgeSide

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def client_binary() -> Path:
    return native_binary("skinet-client")  # the workspace's debug build, shared with tests/dds


@pytest.fixture
def embedded() -> Iterator[tuple[str, BridgeSide, Monitor]]:
    """ACL router, monitor and predictor; yields the endpoint, the bridge's side (the monitor synced
    from it) and the monitor."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(acl_router_config(endpoint))
    sessions = {user: login(endpoint, user) for user in ("monitor", "predictor", "bridge")}
    system, _ = load_system(REPO / "skillsets" / "spot_arm.toml")
    predictor = start_predictor(sessions["predictor"], "rust-test")
    monitor = start_monitor(sessions["monitor"], system, client="monitor")  # asks under its login
    try:
        yield endpoint, BridgeSide(sessions["bridge"], SYSTEM, source="test", model=system), monitor
    finally:
        monitor.close()
        for s in sessions.values():
            s.close()
        predictor.close()
        router.close()


def test_rust_client_queries_the_predictor_and_prints_verdicts(client_binary: Path,
                                                               embedded: tuple[str, BridgeSide, Monitor]) -> None:
    endpoint, bridge, _ = embedded
    proc = subprocess.Popen([str(client_binary), "--connect", endpoint, "--system", SYSTEM, "--user", "monitor",
                             "--password", passwords()["monitor"], "--verdicts", "2", "--timeout", "20"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    following = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            lines.append(line.rstrip())
            if line.startswith("following "):
                following.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert following.wait(30), "the client never subscribed:\n" + "\n".join(lines)
        time.sleep(0.3)  # its subscription reaches the router
        for transition in ("init_power.start", "init_power.success.powered_on"):
            bridge.send("spot", transition)
        assert proc.wait(timeout=30) == 0, "\n".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
        reader.join(timeout=5)
    out = "\n".join(lines)
    print(out)
    assert lines[0].startswith(f"model {SYSTEM} "), out
    assert any(line.startswith("prediction by rust-test: ") and " markings, " in line for line in lines), out
    verdicts = [line for line in lines if line.startswith("verdicts #")]
    assert len(verdicts) == 2, out
    assert all("action_guard=holds" in v and "safety_guard=holds" in v for v in verdicts), out


def test_rust_client_asks_the_command_check(client_binary: Path,
                                           embedded: tuple[str, BridgeSide, Monitor]) -> None:
    endpoint, bridge, monitor = embedded
    # An allow needs a synced state and a fresh prediction; the client asks without waiting.
    deadline = time.monotonic() + 20
    while monitor.check(CheckRequest(skillset="spot", transition="init_power.start")).decision != "allow":
        assert time.monotonic() < deadline, "the monitor never answered allow"
        time.sleep(0.05)
    out = subprocess.run([str(client_binary), "--connect", endpoint, "--system", SYSTEM, "--user", "observer",
                          "--password", passwords()["observer"], "--check", "spot:init_power.start",
                          "--check", "spot:telop.start", "--verdicts", "0"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out
    lines = out.stdout.splitlines()
    assert "check spot:init_power.start: allow" in lines, out.stdout
    assert any(line.startswith("check spot:telop.start: unknown transition 'telop.start' of skillset 'spot' "
                               "(candidates: teleop.start") for line in lines), out.stdout
    # The bridge gone: the answer carries fields this client does not know (state_stale, state_reason);
    # serde ignores them, and the client shows the warning and its reason kind.
    bridge.close()
    deadline = time.monotonic() + 10
    while not monitor.check(CheckRequest(skillset="spot", transition="init_power.start")).state_stale:
        assert time.monotonic() < deadline, "the monitor never lost the bridge"
        time.sleep(0.05)
    out = subprocess.run([str(client_binary), "--connect", endpoint, "--system", SYSTEM, "--user", "observer",
                          "--password", passwords()["observer"], "--check", "spot:init_power.start",
                          "--verdicts", "0"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out
    lines = out.stdout.splitlines()
    assert "check spot:init_power.start: warn" in lines and any("state_unknown (warn)" in line for line in lines), \
        out.stdout

"""SkiNet Live in Foxglove: ``python -m services.foxglove`` seen by a ``foxglove.websocket.v1`` client.

The server runs as its own process, a read-only client of a loopback router;
the paper's unassisted run is played through simulator, bridge, monitor and
predictor on another client; a protocol client (tests/services/foxglove_client.py)
subscribes to every advertised channel and decodes each message against its schema.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from skinet.mission.scenario import StepRecord
from skinet.wire import foxglove as fx
from tests.services.conftest import REPO, client_args, free_port
from tests.services.foxglove_client import FoxgloveClient
from tests.services.test_dashboard import SYSTEM_FILE, VIOLATIONS, play


@pytest.fixture
def foxglove(spawn: Callable, router: str) -> Iterator[Callable[[], FoxgloveClient]]:
    clients: list[FoxgloveClient] = []

    def start() -> FoxgloveClient:
        port = free_port()
        spawn("services.foxglove", str(SYSTEM_FILE), "--port", str(port), "--wait", "1", *client_args(router))
        client = FoxgloveClient(f"ws://127.0.0.1:{port}")
        clients.append(client)
        return client

    yield start
    for c in clients:
        c.close()


def violations_at_their_steps(client: FoxgloveClient, seen: list[tuple[str, int, str]]) -> Callable[[StepRecord], None]:
    """A chain's ``on_record``: after each step of the unassisted run, wait for its series and for the violations so
    far on ``client``; each new one goes to ``seen`` as (property, step, event)."""
    def after(record: StepRecord) -> None:
        client.wait(lambda c: any(m["seq"] == record.index for m in c.on(fx.SERIES)), f"the series of step "
                    f"{record.index}")
        expected = [v for v in VIOLATIONS if v[1] <= record.index]
        client.wait(lambda c: len(c.on(fx.VIOLATIONS)) == len(expected),
                    f"{len(expected)} violation(s) after step {record.index}")
        if record.violations:
            v = client.on(fx.VIOLATIONS)[-1]
            seen.append((v["property"], v["seq"], v["event"].split("#")[0]))
    return after


def test_the_unassisted_run_in_foxglove_shows_each_violation_at_its_step(foxglove, router) -> None:
    client = foxglove()
    client.wait(lambda c: len(c.channels) == len(fx.channels()), "every channel advertised")
    advertised = client.topics()
    assert {t: (c["encoding"], c["schemaName"], c["schemaEncoding"]) for t, c in advertised.items()} == {
        s.topic: ("json", s.schema_name, "jsonschema") for s in fx.channels()}
    assert client.protocol == "foxglove.sdk.v1"
    assert client.server_info is not None and client.server_info["name"] == "SkiNet Live spot_arm"
    seen: list[tuple[str, int, str]] = []
    records = play("unassisted", router, violations_at_their_steps(client, seen))
    assert seen == VIOLATIONS
    assert [(p, r.index) for r in records for p in r.violations] == [(p, i) for p, i, _ in VIOLATIONS]
    assert client.invalid == []
    # Plot series: violations so far counted up at each onset.
    series = {m["seq"]: m for m in client.on(fx.SERIES)}
    assert [series[i]["violations"] for _, i, _ in VIOLATIONS] == [1, 2, 3]
    assert series[VIOLATIONS[0][1] - 1]["violations"] == 0
    # One foxglove.Log line per step, an error line per violation.
    lines = [m["message"] for m in client.on(fx.LOG)]
    assert sum(line.startswith(f"step {records[-1].index}: ") for line in lines) >= 1
    assert [line for line in lines if "VIOLATED" in line] == [
        f"step {i}: VIOLATED {p} at {e}" for p, i, e in
        [(v["property"], v["seq"], v["event"]) for v in client.on(fx.VIOLATIONS)]]
    assert any(m["properties"] for m in client.on(fx.VERDICTS))
    assert client.on(fx.STATE_SPACE) and client.on(fx.STATE)[-1]["seq"] == records[-1].index


def test_the_view_does_nothing_without_a_subscriber_and_wakes_up_where_the_run_is(router, client_factory) -> None:
    """In process: no client, nothing translated; a client joining at step 27 gets the last state and the series
    counting the violation it missed (not the violation again); gone at step 33, the view sleeps; another client at
    step 37 starts from there and sees the violation of step 38 once."""
    from services.dashboard.observer import Observer
    from services.foxglove.server import FoxgloveView
    from skinet.system.load import load_system
    from tests.services.test_monitor import wait_until

    observer = Observer(client_factory(), "spot_arm", load_system(SYSTEM_FILE)[0])
    view = FoxgloveView(observer, "127.0.0.1", 0)
    clients: list[FoxgloveClient] = []
    translated: list[int] = []

    def join(step: int) -> FoxgloveClient:
        wait_until(lambda: observer.read(lambda b: b.unsafe is not None and b.unsafe.seq == step), 20,
                   f"the observer at step {step}")
        clients.append(FoxgloveClient(view.url))
        clients[-1].wait(lambda c: c.on(fx.STATE) and c.on(fx.SERIES), "the last state and series")
        return clients[-1]

    def after(record: StepRecord) -> None:
        if record.index == 27:
            assert (view.idle, view.translated, view.sent, view.caught_up) == (True, 0, 0, 0)
            client = join(27)
            assert (client.on(fx.STATE)[-1]["seq"], client.on(fx.SERIES)[-1]["violations"]) == (27, 1)
            assert view.caught_up == 1 and not view.idle and client.on(fx.VIOLATIONS) == []
        elif record.index == 33:
            clients[0].wait(lambda c: len(c.on(fx.VIOLATIONS)) == 1, "the violation of step 33")
            clients[0].close()
            wait_until(lambda: view.idle, 10, "the view asleep")
            translated.append(view.translated)
        elif record.index == 37:
            assert view.translated == translated[0]  # steps 34 to 37: nothing done
            client = join(37)
            assert (client.on(fx.STATE)[-1]["seq"], client.on(fx.SERIES)[-1]["violations"]) == (37, 2)
            assert view.caught_up == 2

    try:
        play("unassisted", router, after)
        clients[1].wait(lambda c: c.on(fx.VIOLATIONS), "the violation of step 38")
        assert [(v["property"], v["seq"]) for c in clients for v in c.on(fx.VIOLATIONS)] == [
            (p, i) for p, i, _ in VIOLATIONS[1:]]
        assert [c.invalid for c in clients] == [[], []]
    finally:
        for c in clients:
            c.close()
        view.close()
        observer.close()


def test_a_port_in_use_is_a_one_line_error(router) -> None:
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        done = subprocess.run([sys.executable, "-m", "services.foxglove", str(SYSTEM_FILE), "--port", str(port),
                               *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    errors = [line for line in done.stderr.splitlines() if "error" in line]
    assert errors == [f"python -m services.foxglove: error: cannot serve Foxglove on 127.0.0.1:{port}: "
                      + errors[0].split(f"127.0.0.1:{port}: ", 1)[1]]
    assert "Traceback" not in done.stderr


def test_skinet_run_serves_foxglove_and_a_late_subscriber_gets_the_last_state() -> None:
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--duration", "30",
                             "--no-multicast-scouting", "--no-pilot", "--foxglove", str(port)], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    client = None
    try:
        assert proc.stderr.readline().strip() == f"foxglove on ws://127.0.0.1:{port}"
        client = FoxgloveClient(f"ws://127.0.0.1:{port}")
        # No bridge: step 0 only, published before the client came; it is sent again on subscription,
        # saying that the monitor cannot vouch for the marking.
        client.wait(lambda c: c.on(fx.STATE) and c.on(fx.STATE_SPACE), "the state and the state space")
        state = client.on(fx.STATE)[-1]
        assert state["seq"] == 0 and {n: s["state"] for n, s in state["sync"].items()} == {
            "spot": "syncing", "manipulator": "syncing"}
        assert client.on(fx.STATE_SPACE)[-1]["markings"] > 0
        assert client.invalid == []
    finally:
        if client is not None:
            client.close()
        proc.terminate()
        assert proc.wait(15) == 0


def test_skinet_runs_foxglove_view_ends_with_it_even_when_killed() -> None:
    """The view is fed through a pipe: killed, ``skinet run`` leaves no view holding the port."""
    import signal

    from tests.services.test_monitor import wait_until

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--duration", "60",
                             "--no-multicast-scouting", "--no-pilot", "--foxglove", str(port)], cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stderr.readline().strip() == f"foxglove on ws://127.0.0.1:{port}"
        children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
        views = [int(c) for c in children if "services.foxglove" in Path(f"/proc/{c}/cmdline").read_text()]
        assert len(views) == 1
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)

        def gone() -> bool:  # ended: no such process, or a zombie its new parent has not reaped
            try:
                return "\nState:\tZ" in Path(f"/proc/{views[0]}/status").read_text()
            except FileNotFoundError:
                return True
        wait_until(gone, 30, "the view's process gone with skinet run")
    finally:
        proc.kill()
        proc.wait()


def test_the_layout_opens_a_panel_on_every_channel_and_names_no_other_topic() -> None:
    import json
    import re

    layout = json.loads((REPO / "docs" / "foxglove-layout.json").read_text())
    used = set()
    for config in layout["configById"].values():
        paths = [config.get("topicPath"), config.get("topicToRender"), *(p["value"] for p in config.get("paths", []))]
        used |= {re.match(r"(/skinet/\w+)", p).group(1) for p in paths if p}  # type: ignore[union-attr]
    assert used == {s.topic for s in fx.channels()}
    panels = set(re.findall(r'"(\w+![\w-]+)"', json.dumps(layout["layout"])))
    assert panels == set(layout["configById"])


def test_skinet_run_with_a_foxglove_port_in_use_stops_with_one_line() -> None:
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        done = subprocess.run([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--once",
                               "--no-multicast-scouting", "--no-pilot", "--foxglove", str(port)], cwd=REPO,
                              capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith(f"skinet: error: --foxglove: cannot serve Foxglove on 127.0.0.1:{port}: ")
    assert len(done.stderr.splitlines()) == 1, done.stderr


def test_a_burst_sends_the_last_state_of_each_round_and_a_log_line_for_every_step(router, client_factory) -> None:
    """200 steps published at once: the live picture's channel gets the last state of each sending round (the others
    are counted, never sent), the log one line per step, in order."""
    from services.dashboard.observer import Observer
    from services.foxglove.server import FoxgloveView
    from skinet.system.load import load_system
    from skinet.wire import keys
    from skinet.wire.codec import encode
    from skinet.wire.messages import LiveState
    from tests.services.test_monitor import wait_until

    observer = Observer(client_factory(), "spot_arm", load_system(SYSTEM_FILE)[0])
    view = FoxgloveView(observer, "127.0.0.1", 0)
    client = FoxgloveClient(view.url)
    monitor = client_factory()
    try:
        wait_until(lambda: view._subscriptions == len(fx.channels()), 20, "every channel subscribed")
        publisher = monitor.declare_publisher(keys.state("spot_arm"))
        wait_until(lambda: publisher.matching_status.matching, 10, "the observer's subscriber")
        for seq in range(1, 201):
            publisher.put(encode(LiveState(system="spot_arm", seq=seq, stamp=1000.0 + seq, skillsets={},
                                           event=f"spot:teleop.start#{seq}")))
        client.wait(lambda c: any(m["message"].startswith("step 200: ") for m in c.on(fx.LOG)), "step 200's line")
        steps = [m["message"] for m in client.on(fx.LOG) if m["message"].startswith("step ")]
        assert steps == [f"step {seq}: spot:teleop.start#{seq}" for seq in range(1, 201)]
        states = [m["seq"] for m in client.on(fx.STATE)]
        assert states[-1] == 200 and states == sorted(states)
        assert len(states) < 200 and len(states) + view.coalesced == 200, (len(states), view.coalesced)
        assert client.invalid == []
    finally:
        client.close()
        view.close()
        observer.close()

"""SkiNet Live in Foxglove: ``python -m services.foxglove`` seen by a ``foxglove.websocket.v1`` client.

The server runs as its own process, a read-only client of a loopback router;
the paper's unassisted run is played through simulator, bridge, monitor and
predictor on another client; a protocol client (tests/services/foxglove_client.py)
subscribes to every advertised channel and decodes each message against its schema.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from skinet.mission.scenario import StepRecord
from skinet.wire import foxglove as fx
from skinet.wire import keys
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


def test_the_unassisted_run_in_foxglove_shows_each_violation_at_its_step(foxglove, router, client_factory) -> None:
    """Through Zenoh, the view takes the monitor's results in rounds from its feed: it subscribes to none of the
    monitor's five result keys (a probe publisher on each sees no subscriber; one on the feed sees it)."""
    client = foxglove()
    watcher = client_factory()  # its publishers learn of every subscriber the router knows
    probes = {key.__name__: watcher.declare_publisher(key("spot_arm"))
              for key in (keys.state, keys.verdicts, keys.unsafe, keys.state_space, keys.divergences, keys.feed)}
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
    assert [name for name, probe in probes.items() if probe.matching_status.matching] == ["feed"]


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
            wait_until(lambda: view.idle and not view.busy, 10, "the view asleep, done with what it had taken")
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


def test_a_round_of_a_few_steps_sends_its_last_state_and_a_log_line_for_every_step(router, client_factory) -> None:
    """STEPS_PER_ROUND steps in one round (a robot's pace gives far fewer): the live picture's channel gets the last
    state only (the others counted, never sent), the log one line per step, in order."""
    from services.foxglove.translate import STEPS_PER_ROUND
    from skinet.wire.codec import encode
    from skinet.wire.messages import LiveState

    with one_round_view(client_factory) as (observer, view, client):
        with view._cond:  # the view's thread takes nothing before the last step
            for seq in range(1, STEPS_PER_ROUND + 1):
                observer.take(encode(LiveState(system="spot_arm", seq=seq, stamp=1000.0 + seq, skillsets={},
                                               event=f"spot:teleop.start#{seq}")), LiveState, False)
        last = f"step {STEPS_PER_ROUND}: "
        client.wait(lambda c: any(m["message"].startswith(last) for m in c.on(fx.LOG)), "the last step's line")
        steps = [m["message"] for m in client.on(fx.LOG) if m["message"].startswith("step ")]
        assert steps == [f"step {seq}: spot:teleop.start#{seq}" for seq in range(1, STEPS_PER_ROUND + 1)]
        assert [m["seq"] for m in client.on(fx.STATE)] == [STEPS_PER_ROUND]
        assert (view.coalesced, view.skipped, client.invalid) == (STEPS_PER_ROUND - 1, 0, [])


def test_a_flood_shows_its_last_step_says_how_many_it_did_not_and_loses_no_violation(router, client_factory) -> None:
    """The paper's unassisted run and two steps more, every result of the monitor in one round (a replay at full
    speed): one state and one step line, the last; one line for the steps not shown; the violation that began and
    ended among them on its channel at its own step (the board behind the view saw every step)."""
    from services.dashboard.observer import FED
    from services.foxglove.translate import STEPS_PER_ROUND
    from skinet.wire.codec import decode
    from skinet.wire.messages import LiveState
    from tests.services.test_monitor import AG, SG
    from tests.services.test_monitor_feed import monitor_messages

    taken = [(payload, FED[name]) for name, payload in monitor_messages(client_factory)]
    last = [decode(payload, kind).seq for payload, kind in taken if kind is LiveState][-1]
    with one_round_view(client_factory) as (observer, view, client):
        with view._cond:
            for payload, kind in taken:
                observer.take(payload, kind, False)
        skipped = observer.read(lambda b: len(b.points)) - 1
        assert skipped > STEPS_PER_ROUND
        client.wait(lambda c: any("not shown" in m["message"] for m in c.on(fx.LOG)), "the line of the steps not shown")
        lines = [m["message"] for m in client.on(fx.LOG)]
        busy = "spot control_mode at Busy while manipulator mutex at Busy"
        assert [line.split("#")[0] if i < 2 else line for i, line in enumerate(lines)] == [
            f"step 10: VIOLATED {AG} at manipulator:arm_ready.start", f"step {last}: manipulator:arm_RD_to_HP.start",
            f"step {last}: unsafe spot:sit_down.start: explicit for {AG} — violates it at once: {busy}",
            f"step {last}: unsafe spot:go_to_waypoint.start: explicit for {AG} — violates it at once: {busy}",
            f"step {last}: unsafe spot:go_to_waypoint.start: explicit for {SG} — violates it at once: spot "
            "go_to_waypoint runs while manipulator arm_status at Moving",
            f"step {last}: unsafe spot:teleop.start: explicit for {AG} — violates it at once: {busy}",
            f"{skipped} steps before step {last} not shown: more than {STEPS_PER_ROUND} steps in 20 ms, the view "
            "shows the last of each round"]
        assert [(v["property"], v["seq"]) for v in client.on(fx.VIOLATIONS)] == [(AG, 10)]
        assert [m["seq"] for m in client.on(fx.STATE)] == [last]
        assert (view.skipped, client.invalid) == (skipped, [])


@contextlib.contextmanager
def one_round_view(client_factory: Callable) -> Iterator[tuple]:
    """A view of an observer fed by the test (``fed=True``: no monitor's key from Zenoh) and a client subscribed to
    every channel; (observer, view, client).  Updates handed to the observer while the test holds ``view._cond``
    make one round."""
    from services.dashboard.observer import Observer
    from services.foxglove.server import FoxgloveView
    from skinet.system.load import load_system
    from tests.services.test_monitor import wait_until

    observer = Observer(client_factory(), "spot_arm", load_system(SYSTEM_FILE)[0], fed=True)
    view = FoxgloveView(observer, "127.0.0.1", 0)
    client = FoxgloveClient(view.url)
    try:
        wait_until(lambda: view._subscriptions == len(fx.channels()), 20, "every channel subscribed")
        yield observer, view, client
    finally:
        client.close()
        view.close()
        observer.close()


def test_a_round_folds_a_flood_as_it_comes_and_counts_a_pipes_readers_steps_in_its_one_line() -> None:
    """A Round past STEPS_PER_ROUND steps that holds a pipe reader's own note of 5 steps left out: the violation
    and the pilot change in order, the last of the picture, one note for 5 + 10 steps; once past, it keeps no
    update of the picture but the last of each kind."""
    from services.foxglove.translate import STEPS_PER_ROUND, Round

    def state(seq: int) -> dict:
        return {"kind": "state", "message": {"seq": seq}}

    few = Round(STEPS_PER_ROUND, 0.02)
    steps = [state(seq) for seq in range(1, STEPS_PER_ROUND + 1)]
    few.add(steps)
    assert (few.flood, few.shown()) == (False, steps)
    note = {"kind": "skipped", "steps": 5, "most": STEPS_PER_ROUND, "round": 0.02}
    violation, pilot = {"kind": "violation", "violation": {"seq": 3}}, {"kind": "pilot", "message": {}}
    verdicts = [{"kind": "verdicts", "message": {"seq": seq}} for seq in (2, 11, 12)]
    flood = Round(STEPS_PER_ROUND, 0.1)
    flood.add([note, state(1), state(2), verdicts[0], {"kind": "point", "point": {}}, violation, *steps[2:], pilot,
               state(11), verdicts[1]])
    flood.add([state(12), {"kind": "point", "point": {}}, verdicts[2]])
    assert flood.flood and len(flood.updates) == STEPS_PER_ROUND + 5  # the 11th step on: the last of each kept
    assert flood.shown() == [violation, pilot, state(12), verdicts[2],
                             {"kind": "skipped", "steps": 5 + STEPS_PER_ROUND + 1, "most": STEPS_PER_ROUND,
                              "round": 0.1}]

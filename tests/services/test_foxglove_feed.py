"""The Foxglove view of ``skinet run --foxglove`` fed through a pipe (services/foxglove/feed.py).

Real parts: a loopback router, the monitor on a client of it, an OS pipe, the view as
``python -m services.foxglove --feed FD`` and a ``foxglove.websocket.v1`` client
(tests/services/foxglove_client.py); the paper's unassisted run played through the whole chain.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import zenoh

from services.dashboard.observer import Observer
from services.foxglove.feed import PipeFeed, PipeReader
from services.monitor import start_monitor
from skinet.mission.scenario import StepRecord
from skinet.system.load import load_system
from skinet.wire import foxglove as fx
from skinet.wire import keys
from tests.bridge_side import BridgeSide
from tests.processes import start_module, stop
from tests.services.conftest import client_args, free_port
from tests.services.foxglove_client import FoxgloveClient
from tests.services.test_dashboard import SYSTEM_FILE, VIOLATIONS, play
from tests.services.test_monitor import wait_until

MISSION = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
           ("spot", "stand_up.success.standing"), ("spot", "sit_down.start"), ("spot", "sit_down.success.sitting"),
           ("spot", "safe_poweroff.start"), ("spot", "safe_poweroff.success.powered_off")]


def matched(session: zenoh.Session, key: str) -> bool:
    """Whether a subscriber of ``key`` is reachable from ``session`` now."""
    publisher = session.declare_publisher(key)
    try:
        return publisher.matching_status.matching
    finally:
        publisher.undeclare()


def test_the_view_shows_each_violation_at_its_step_with_no_subscriber_of_the_monitors_keys(
        router: str, client_factory: Callable[[], zenoh.Session], tmp_path) -> None:
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    port = free_port()
    view = start_module("services.foxglove", str(SYSTEM_FILE), "--port", str(port), "--wait", "1", "--feed", str(read),
                        *client_args(router), log=tmp_path / "view.log", pass_fds=(read,))
    os.close(read)
    client = FoxgloveClient(f"ws://127.0.0.1:{port}")
    watcher = client_factory()
    try:
        client.wait(lambda c: len(c.channels) == len(fx.channels()), "every channel advertised")
        seen: list[tuple[str, int, str]] = []

        def after(record: StepRecord) -> None:
            client.wait(lambda c: any(m["seq"] == record.index for m in c.on(fx.SERIES)),
                        f"the series of step {record.index}")
            expected = [v for v in VIOLATIONS if v[1] <= record.index]
            client.wait(lambda c: len(c.on(fx.VIOLATIONS)) == len(expected),
                        f"{len(expected)} violation(s) after step {record.index}")
            if record.violations:
                v = client.on(fx.VIOLATIONS)[-1]
                seen.append((v["property"], v["seq"], v["event"].split("#")[0]))

        play("unassisted", router, after, tap=feed.record)
        assert seen == VIOLATIONS
        assert feed.dropped == 0 and client.invalid == []
        # The view asked for the monitor's results on no key: the monitor's puts reach no other process.
        assert [k for k in (keys.state, keys.verdicts, keys.unsafe, keys.state_space, keys.divergences)
                if matched(watcher, k("spot_arm"))] == []
        unfed = Observer(client_factory(), "spot_arm")  # as skinet foxglove observes: the same check sees it
        wait_until(lambda: matched(watcher, keys.verdicts("spot_arm")), 10, "an unfed observer's subscriber")
        unfed.close()
        feed.close()  # skinet run gone: its view ends with the pipe
        assert view.wait(20) == 0
    finally:
        client.close()
        feed.close()
        stop(view)


def test_a_full_pipe_is_a_gap_and_the_view_catches_up_from_the_monitor(
        client_factory: Callable[[], zenoh.Session]) -> None:
    system = load_system(SYSTEM_FILE)[0]
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    feed.budget = 8192  # a few steps' worth
    session = client_factory()
    monitor = start_monitor(session, system, tap=feed.record)
    side = BridgeSide(session, "spot_arm", model=system)
    ended = threading.Event()
    reader = None
    try:
        step = 0

        def send(n: int) -> None:
            nonlocal step
            for _ in range(n):
                skillset, transition = MISSION[step % len(MISSION)]
                side.send(skillset, transition)
                step += 1
                wait_until(lambda: monitor.snapshot().state.seq == step, 10, f"the monitor's step {step}")

        while feed.dropped == 0:
            send(1)
        send(2)
        written = feed.sent
        observer = Observer(client_factory(), "spot_arm", system, fed=True)
        reader = PipeReader(read, observer, ended)
        wait_until(lambda: reader.messages == written and observer.read(
            lambda b: b.unsafe is not None and b.unsafe.seq == step), 10, f"every frame, and step {step} caught up")
        # One gap: the monitor's last results were asked at the start and at the gap mark; every frame read was
        # taken as what it may be, an older copy, never as a restarted monitor.
        assert (feed.gaps, reader.gaps, observer.read(lambda b: (b.state.seq, b.verdicts.seq, b.epoch))) == (
            1, 1, (step, step, 0))
        send(1)  # the pipe has room again: the next step comes through it
        wait_until(lambda: observer.read(lambda b: b.unsafe is not None and b.unsafe.seq == step), 10,
                   f"step {step} through the pipe")
        assert reader.messages > written and (feed.gaps, reader.gaps) == (1, 1)
        feed.close()
        assert ended.wait(5)
        observer.close()
    finally:
        if reader is not None:
            reader.close()
        feed.close()
        side.close()
        monitor.close()

"""The Foxglove view of ``skinet run --foxglove`` fed through a pipe (services/foxglove/feed.py).

Real parts: a loopback router, the monitor on a client of it, an OS pipe, the view as
``python -m services.foxglove --feed FD`` and a ``foxglove.websocket.v1`` client
(tests/services/foxglove_client.py); the paper's unassisted run played through the whole chain.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable

import pytest
import zenoh

from services.dashboard.observer import Observer
from services.foxglove import feed as feed_module
from services.foxglove.feed import PipeFeed, PipeReader
from services.monitor import start_monitor
from skinet.system.load import load_system
from skinet.wire import foxglove as fx
from skinet.wire import keys
from tests.bridge_side import BridgeSide
from tests.processes import start_module, stop
from tests.services.conftest import client_args, free_port
from tests.services.foxglove_client import FoxgloveClient
from tests.services.test_dashboard import SYSTEM_FILE, VIOLATIONS, play
from tests.services.test_foxglove import violations_at_their_steps
from tests.services.test_monitor import wait_until

MISSION = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
           ("spot", "stand_up.success.standing"), ("spot", "sit_down.start"), ("spot", "sit_down.success.sitting"),
           ("spot", "safe_poweroff.start"), ("spot", "safe_poweroff.success.powered_off")]


def stop_feeding(reader: PipeReader | None, feed: PipeFeed, side: BridgeSide, monitor) -> None:
    """The end of a test of the pipe: its reader, its writer, the bridge's side, the monitor."""
    if reader is not None:
        reader.close()
    feed.close()
    side.close()
    monitor.close()


def test_the_view_shows_each_violation_at_its_step_with_no_subscriber_of_the_monitors_keys(
        router: str, client_factory: Callable[[], zenoh.Session], tmp_path) -> None:
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    port = free_port()
    view = start_module("services.foxglove", str(SYSTEM_FILE), "--port", str(port), "--wait", "1", "--feed", str(read),
                        *client_args(router), log=tmp_path / "view.log", pass_fds=(read,))
    os.close(read)
    client = FoxgloveClient(f"ws://127.0.0.1:{port}")
    watcher = client_factory()  # its publishers learn of every subscriber of the monitor's keys the router knows
    probes = {key.__name__: watcher.declare_publisher(key("spot_arm"))
              for key in (keys.state, keys.verdicts, keys.unsafe, keys.state_space, keys.divergences)}
    try:
        client.wait(lambda c: len(c.channels) == len(fx.channels()), "every channel advertised")
        seen: list[tuple[str, int, str]] = []
        play("unassisted", router, violations_at_their_steps(client, seen), tap=feed.record)
        assert seen == VIOLATIONS
        assert feed.dropped == 0 and client.invalid == []
        # The view subscribed to none of the monitor's results: the monitor's puts reach no other process.
        assert [name for name, probe in probes.items() if probe.matching_status.matching] == []
        unfed = Observer(client_factory(), "spot_arm")  # as skinet foxglove observes: the same probe sees it
        wait_until(lambda: probes["verdicts"].matching_status.matching, 10, "an unfed observer's subscriber")
        unfed.close()
        feed.close()  # skinet run gone: its view ends with the pipe
        assert view.wait(20) == 0
    finally:
        client.close()
        feed.close()
        stop(view)


def test_a_full_pipe_is_a_gap_and_the_view_comes_back_to_the_present(
        client_factory: Callable[[], zenoh.Session]) -> None:
    """Three ways back after the pipe was full: at the reader's start (it asks the monitor first), when the monitor
    writes again (the last of each kind dropped, then the new step), and when it stays quiet after the gap (the
    reader asks it after QUIET); never a restarted monitor, never a frame taken twice."""
    from services.foxglove.feed import QUIET

    system = load_system(SYSTEM_FILE)[0]
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    session = client_factory()
    monitor = start_monitor(session, system, tap=feed.record)
    side = BridgeSide(session, "spot_arm", model=system)
    ended = threading.Event()
    reader = None
    try:
        step = 0

        def send(n: int) -> None:  # n steps at once, then until the monitor made them
            nonlocal step
            for _ in range(n):
                skillset, transition = MISSION[step % len(MISSION)]
                side.send(skillset, transition)
                step += 1
            wait_until(lambda: monitor.snapshot().state.seq == step, 10, f"the monitor's step {step}")

        def shown() -> tuple[int, int, int]:
            return observer.read(lambda b: (b.state.seq, b.verdicts.seq, b.unsafe.seq) if b.unsafe else (-1,) * 3)

        feed.budget = 8192  # a few steps' worth
        while feed.dropped == 0:
            send(1)
        send(2)
        observer = Observer(client_factory(), "spot_arm", system, fed=True)
        reader = PipeReader(read, observer, ended)
        wait_until(lambda: reader.gaps == 1 and shown() == (step,) * 3, 10, f"the gap mark, and step {step}")
        assert (feed.gaps, observer.read(lambda b: b.epoch)) == (1, 0)  # older copies never taken for a restart
        send(1)  # the feed writes again: the last of each kind it dropped, then this step
        wait_until(lambda: shown() == (step,) * 3, 10, f"step {step} through the pipe")
        assert (feed.gaps, reader.gaps) == (1, 1)
        feed.budget = 1200  # one step's worth: two at once make a gap with the reader running
        while feed.gaps == 1:
            send(2)
        written = feed.sent
        wait_until(lambda: shown() == (step,) * 3, QUIET + 10, f"step {step}, asked after the gap")
        # Nothing was written since the gap: the step came from the reader's question to the quiet monitor.
        assert (feed.sent, feed.gaps, reader.gaps, observer.read(lambda b: b.epoch)) == (written, 2, 2, 0)
        feed.close()
        assert ended.wait(5)
        observer.close()
    finally:
        stop_feeding(reader, feed, side, monitor)


def test_a_flood_of_steps_shows_the_last_complete_step_and_each_onset_at_its_step(
        client_factory: Callable[[], zenoh.Session]) -> None:
    """More than STEPS_PER_ROUND steps in a round (a replay at full speed): the view takes the last complete step,
    says in its log how many it did not show, and still lists the violation that began and ended among them at
    its own step (from the monitor's list); the step left for the next round comes then."""
    from chains.embedded import taps
    from services.common.zenoh_config import session_config
    from services.foxglove.translate import STEPS_PER_ROUND, Translator
    from skinet.wire.codec import decode
    from skinet.wire.messages import UnsafeReport
    from tests.services.test_monitor import AG, PAPER_STEPS

    system = load_system(SYSTEM_FILE)[0]
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    states: list[bytes] = []
    reports: list[bytes] = []  # tapped after the feed: the last one is in the pipe
    alone = zenoh.open(session_config("peer", multicast_scouting=False))  # the view's catch-up finds no monitor
    monitor = start_monitor(alone, system, tap=taps(feed.record, lambda k, p, t=0.0: k == keys.state("spot_arm")
                                                                and states.append(p),
                                                    lambda k, p, t=0.0: k == keys.unsafe("spot_arm")
                                                                and reports.append(p)))
    side = BridgeSide(alone, "spot_arm", model=system)
    reader = None
    try:
        steps = [(s, t) for s, t, _, _ in PAPER_STEPS] + [("manipulator", "arm_ready.success.ready"),
                                                           ("manipulator", "arm_RD_to_HP.start")]
        for skillset, transition in steps:
            side.send(skillset, transition)
        # The step's report is written after its snapshot: a reader started between them saw one more step apart.
        wait_until(lambda: reports and decode(reports[-1], UnsafeReport).seq == len(steps), 10,
                   "the monitor's last step in the pipe")
        assert len(states) > STEPS_PER_ROUND + 1
        observer = Observer(client_factory(), "spot_arm", system, fed=True)
        updates: list[dict] = []
        observer.listen(updates.extend)
        reader = PipeReader(read, observer, threading.Event())
        wait_until(lambda: observer.read(lambda b: b.state is not None and b.state.seq == len(steps)), 10,
                   "the step left for the next round")
        shown = [u["message"]["seq"] for u in updates if u["kind"] == "state"]
        assert shown == [len(steps) - 1, len(steps)]
        assert reader.skipped == len(states) - 2  # every state but the one shown and the one left for later
        assert [(v["property"], v["seq"], v["event"].split("#")[0]) for v in observer.read(lambda b: b.violations)] == [
            (AG, 10, "manipulator:arm_ready.start")]
        logs = [m["message"] for topic, m, _ in Translator("spot_arm").feed(updates) if topic == fx.LOG]
        assert f"{len(states) - 2} steps before step {len(steps) - 1} not shown: more than {STEPS_PER_ROUND} steps " \
               f"in 20 ms, the view shows the last of each round" in logs
        observer.close()
    finally:
        stop_feeding(reader, feed, side, monitor)
        alone.close()


def test_an_idle_reader_sleeps_on_the_pipe_and_the_first_write_wakes_it(client: zenoh.Session,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """With nothing written the reader reads the pipe once (at start), not every 20 ms; a write wakes it, and
    close() wakes it (its looks at ``ended`` an hour apart here: the join would time out after 5 s)."""
    from skinet.wire.codec import encode
    from skinet.wire.messages import UnsafeReport

    monkeypatch.setattr(feed_module, "IDLE_LOOK", 3600.0)
    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    observer = Observer(client, "spot_arm", fed=True)
    reader = PipeReader(read, observer, threading.Event())
    try:
        wait_until(lambda: reader.rounds == 1, 10, "the first read")
        time.sleep(1.5)  # 75 rounds of 20 ms
        assert reader.rounds == 1
        feed.record(keys.unsafe("spot_arm"), encode(UnsafeReport(system="spot_arm", seq=1, stamp=1.0, unsafe=[],
                                                                 literal_count=0, prediction_stale=True)))
        wait_until(lambda: reader.messages == 1, 10, "the report read")
        reader.close()
        assert not reader._thread.is_alive()
    finally:
        reader.close()
        feed.close()
        observer.close()


def test_a_feed_whose_view_is_gone_stops_writing_and_never_raises() -> None:
    """The view's process died (its end of the pipe closed): the monitor's tap neither raises nor kills the
    process (EPIPE, not SIGPIPE), and writes nothing more."""
    from skinet.wire.codec import encode
    from skinet.wire.messages import UnsafeReport

    read, write = os.pipe()
    feed = PipeFeed("spot_arm", write)
    os.close(read)
    report = encode(UnsafeReport(system="spot_arm", seq=1, stamp=1.0, unsafe=[], literal_count=0,
                                 prediction_stale=True))
    for _ in range(2):
        feed.record(keys.unsafe("spot_arm"), report)
    assert (feed.sent, feed.dropped) == (0, 0)
    feed.close()

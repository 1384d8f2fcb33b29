"""Model divergences and manager restarts stay visible (issue 27 item 4; docs/semantics.md §7).

The monitor keeps the list of its run (the last 256, with the count of older ones),
publishes it on ``skinet/<system>/divergences`` when it changes and answers ``get``
there, so that views which join late get the list so far.  Real Zenoh sessions through
a loopback router; the manager restart is the simulator's, seen by the real bridge.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import msgpack
import zenoh

from services.bridge_ros2 import start_bridge
from services.monitor import start_monitor
from services.monitor.divergences import DivergenceLog
from services.simulator import Simulator
from skinet.mission.scenario import parse_scenario
from skinet.ros.keys import KeyStyle
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import CanonicalEvent, Divergence, Divergences, LiveState
from skinet.system.load import load_system
from tests.services.test_bridge import CHAIN
from tests.services.test_monitor import SYSTEM_FILE, Events, wait_until

NOT_ENABLED = "'init_power.success.powered_on' is not enabled in the live marking"
# Ten steps of the paper's mission after the divergence (spot powers on, stands, walks, sits).
TEN = [("spot", "init_power.start"), ("spot", "init_power.success.powered_on"), ("spot", "stand_up.start"),
       ("spot", "stand_up.success.standing"), ("spot", "go_to_waypoint.start"),
       ("spot", "go_to_waypoint.success.arrived"), ("spot", "teleop.start"), ("spot", "teleop.success.done"),
       ("spot", "sit_down.start"), ("spot", "sit_down.success.sitting")]


class Lists:
    """The Divergences messages published on a system's key, in arrival order."""

    def __init__(self, session: zenoh.Session, system: str = "spot_arm"):
        self.items: list[Divergences] = []
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(keys.divergences(system), self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._cond:
            self.items.append(decode(sample.payload.to_bytes(), Divergences))
            self._cond.notify_all()

    def wait(self, total: int, timeout: float = 10.0) -> Divergences:
        """The first list with ``total`` entries noted (listed or older)."""
        with self._cond:
            assert self._cond.wait_for(lambda: any(m.older + len(m.entries) == total for m in self.items), timeout), \
                [(m.older, len(m.entries)) for m in self.items]
            return next(m for m in self.items if m.older + len(m.entries) == total)


def ask(session: zenoh.Session, key: str, kind: type) -> list:
    return [decode(r.ok.payload.to_bytes(), kind) for r in session.get(key, timeout=2.0) if r.ok is not None]


def event(seq: int, transition: str | None = "pick.start", restart: bool = False, info: str = "") -> CanonicalEvent:
    return CanonicalEvent(system="s", skillset="arm", seq=seq, stamp=0.0, source="b", epoch=1, transition=transition,
                          restart=restart, info=info)


def test_the_log_keeps_the_last_entries_and_packs_what_the_codec_encodes() -> None:
    log = DivergenceLog("s", "m1", size=3)
    assert log.note(event(0), None, 1, 10.0) is None  # explained by the model, no restart: nothing to keep
    for seq in range(1, 6):
        assert log.note(event(seq), f"why {seq}", seq, 10.0 + seq).n == seq - 1
    assert log.note(event(5), "why 5", 5, 16.0) is None  # the same event again (a duplicate) is noted once
    restart = log.note(event(6, None, restart=True, info="manager restarted (x); same state as before"), None, 5, 17.0)
    assert (restart.kind, restart.event, restart.reason, restart.n) == ("restart", "arm:status#6", "", 5)
    assert (log.total, log.older) == (6, 3)
    payload = log.payload(20.0)
    message = decode(payload, Divergences)
    assert payload == encode(message)  # byte for byte what the codec gives
    assert (message.older, [e.n for e in message.entries]) == (3, [3, 4, 5])
    assert message.entries[0] == Divergence(n=3, kind="divergence", seq=4, stamp=14.0, skillset="arm",
                                            event="arm:pick.start#4", reason="why 4")
    assert msgpack.unpackb(DivergenceLog("s", "m2").payload(1.0)) == {
        "v": 1, "system": "s", "monitor": "m2", "stamp": 1.0, "older": 0, "entries": []}
    # A forged event's texts are cut: a full list stays small whatever the events carry.
    huge = log.note(event(7, "x" * 60_000, restart=True, info="y" * 60_000), "z" * 60_000, 6, 18.0)
    assert [len(t) for t in (huge.event, huge.reason, huge.info)] == [500, 500, 500] and huge.info.endswith("\u2026")


def test_a_divergence_outlives_its_step_and_late_joiners_get_the_list(router, client_factory) -> None:
    system, _ = load_system(SYSTEM_FILE)
    session, observer = client_factory(), client_factory()
    monitor = start_monitor(session, system)
    try:
        # Before any divergence a late joiner learns that there is none (not silence).
        [empty] = ask(observer, keys.divergences("spot_arm"), Divergences)
        assert (empty.monitor, empty.older, empty.entries) == (monitor.instance_id, 0, [])
        lists = Lists(observer)
        events = Events(client_factory())
        events.send("spot", "init_power.success.powered_on")  # init_power never started: a model divergence
        published = lists.wait(1)
        for skillset, transition in TEN:
            events.send(skillset, transition)
        wait_until(lambda: monitor.snapshot().state.seq == 11, 10, "ten more steps")
        [state] = ask(observer, keys.state("spot_arm"), LiveState)
        assert state.seq == 11 and state.divergence is None  # the step's banner is gone ...
        [later] = ask(observer, keys.divergences("spot_arm"), Divergences)  # ... the list is not
        assert later == published == monitor.divergences()
        [entry] = later.entries
        assert (entry.n, entry.kind, entry.seq, entry.skillset, entry.event, entry.reason, entry.info) == (
            0, "divergence", 1, "spot", "spot:init_power.success.powered_on#1", NOT_ENABLED, "")
        assert abs(entry.stamp - time.time()) < 30
    finally:
        monitor.close()


def test_the_list_is_bounded_and_a_burst_is_few_messages(router, client_factory) -> None:
    system, _ = load_system(SYSTEM_FILE)
    session, observer = client_factory(), client_factory()
    monitor = start_monitor(session, system)
    try:
        lists = Lists(observer)
        events = Events(client_factory())
        for _ in range(300):
            events.send("spot", "init_power.success.powered_on")
        last = lists.wait(300)
        assert (last.older, len(last.entries), last.entries[0].n, last.entries[-1].n) == (44, 256, 44, 299)
        assert [e.seq for e in last.entries] == list(range(45, 301))  # each made its own step
        assert ask(observer, keys.divergences("spot_arm"), Divergences) == [last]
        # Published at most every 0.1 s: 300 divergences sent in a burst are not 300 messages.
        assert len(lists.items) < 300
        assert monitor.counters.divergences == 300
    finally:
        monitor.close()


def test_a_manager_restart_seen_by_the_bridge_is_listed(router, client_factory, spot_arm) -> None:
    """rmw_zenoh keys: the restarted manager's token leaves and comes back; the bridge says so in its
    event (``restart``), and the monitor lists it with the bridge's words, however it applied the event."""
    system, typemap = spot_arm
    style = KeyStyle(rmw_zenoh=True, domain=11)
    session, observer = client_factory(), client_factory()
    monitor = start_monitor(session, system)
    sim = Simulator(client_factory(), system, typemap, style=style)
    bridge = start_bridge(client_factory(), system, typemap, style=style)
    try:
        lists = Lists(observer)
        wait_until(monitor.synced, 10, "the monitor synced")
        chain = parse_scenario(CHAIN, "chain.toml")
        sim.drive(replace(chain, steps=chain.steps[:3]), speed=0)  # spot powers on and starts standing up
        wait_until(lambda: monitor.snapshot().state.seq == 3, 10, "three steps")
        sim.restart("spot")
        [entry] = lists.wait(1).entries
        assert (entry.kind, entry.skillset, entry.info) == (
            "restart", "spot", "manager restarted (the manager (or its gateway) came back); state now differs: power_"
                               "status PowerOn -> PowerOff, control_mode Busy -> Idle, stand_up no longer running")
        # The model explains the new state (power_switchoff, then stand_up's invariant fails): a restart, no
        # divergence, and the step it made (4); or the step shown (3) when the event waited, spot syncing
        # because the bridge's heartbeat said first that its manager restarted and was not heard yet.
        assert (entry.seq in (3, 4), entry.event, entry.reason) == (True, "spot:status#4", "")
        wait_until(lambda: monitor.snapshot().state.skillsets["spot"].resources["power_status"] == "PowerOff", 10,
                   "the restarted manager's state followed")
        assert ask(observer, keys.divergences("spot_arm"), Divergences)[0].entries == [entry]
    finally:
        bridge.close()
        sim.close()
        monitor.close()


def test_the_board_keeps_each_monitor_runs_list_and_ignores_older_copies() -> None:
    from services.dashboard.board import Board

    def listed(monitor: str, older: int, ns: range) -> Divergences:
        return Divergences(system="s", monitor=monitor, stamp=1.0, older=older, entries=[
            Divergence(n=n, kind="divergence", seq=n + 1, stamp=float(n), skillset="arm", event=f"arm:x#{n}",
                       reason="why") for n in ns])

    board = Board("s")
    [u] = board.feed(listed("m1", 0, range(0, 2)), 0.0)
    assert ([d["n"] for d in u["added"]], u["older"]) == ([0, 1], 0)
    assert board.feed(listed("m1", 0, range(0, 2)), 0.0, initial=True) == []  # the start-up query's late copy
    assert board.feed(listed("m1", 0, range(0, 1)), 0.0) == []  # an older list
    [u] = board.feed(listed("m1", 1, range(1, 4)), 0.0)  # the monitor dropped entry 0: the board keeps it
    assert ([d["n"] for d in u["added"]], u["older"]) == ([2, 3], 0)
    [u] = board.feed(listed("m2", 5, range(5, 6)), 0.0)  # a restarted monitor that a late board meets mid-run
    assert ([(d["monitor"], d["n"]) for d in u["added"]], u["older"]) == ([("m2", 5)], 5)
    snap = board.snapshot()
    assert [(d["monitor"], d["n"], d["seq"]) for d in snap["divergences"]] == [
        ("m1", 0, 1), ("m1", 1, 2), ("m1", 2, 3), ("m1", 3, 4), ("m2", 5, 6)]
    assert snap["divergences_older"] == 5


def test_a_view_that_missed_steps_takes_each_onset_from_the_monitors_list_once() -> None:
    """A view that saw the property hold, missed steps (its pipe was full, its link was down) and caught up (the
    list first, then the last state and verdicts, as a catch-up asks them): the onset is at the monitor's step,
    once, not at the step the catch-up shows; an earlier violation that ended is no excuse."""
    from services.dashboard.board import Board
    from services.monitor.violations import onset_reason
    from skinet.wire.messages import PropertyVerdict, Verdicts

    def step(seq: int, holds: bool, initial: bool = False) -> list[dict]:
        return [*board.feed(LiveState(system="s", seq=seq, stamp=float(seq), skillsets={}, event=f"arm:x#{seq}"),
                            float(seq), initial),
                *board.feed(Verdicts(system="s", seq=seq, stamp=float(seq),
                                     properties=[PropertyVerdict(name="p", holds=holds)]), float(seq), initial)]

    def listed(*onsets: int) -> Divergences:
        return Divergences(system="s", monitor="m", stamp=9.0, older=0, entries=[
            Divergence(n=n, kind="violation", seq=seq, stamp=float(seq), skillset="arm", event=f"arm:x#{seq}",
                       reason=onset_reason("p")) for n, seq in enumerate(onsets)])

    board = Board("s")
    step(1, True)
    step(2, False)  # seen live: the onset at step 2
    board.feed(listed(2), 2.0)
    step(3, True)
    # Steps 4 to 8 missed, the property violated again from step 6; the catch-up.
    board.feed(listed(2, 6), 9.0, initial=True)
    step(8, False, initial=True)
    assert [(v["property"], v["seq"], v["event"], v.get("listed", False)) for v in board.violations] == [
        ("p", 2, "arm:x#2", False), ("p", 6, "arm:x#6", True)]


def test_a_violation_that_began_and_ended_is_listed_to_a_view_that_joins_later(router, client_factory) -> None:
    """Issue 30: a view that joined after the paper's violation (arm_ready started while teleop runs, step 10)
    had ended (step 11) never listed it; the monitor now keeps its onset in the run's list."""
    import re
    import subprocess
    import sys

    from tests.services.conftest import REPO, client_args
    from tests.services.test_monitor import AG, PAPER_STEPS

    system, _ = load_system(SYSTEM_FILE)
    session = client_factory()
    monitor = start_monitor(session, system)
    try:
        events = Events(client_factory())
        seqs = [events.send(skillset, transition) for skillset, transition, _, _ in PAPER_STEPS]
        wait_until(lambda: monitor.snapshot().state.seq == 11 and monitor.divergences().entries, 10,
                   "the eleven steps and the list")
        [entry] = monitor.divergences().entries
        assert (entry.n, entry.kind, entry.seq, entry.skillset, entry.event, entry.reason) == (
            0, "violation", 10, "manipulator", f"manipulator:arm_ready.start#{seqs[9]}", f"{AG} is violated from this step")
        watch = subprocess.run([sys.executable, "-m", "skinet_cli.main", "watch", "spot_arm", "--once", "--wait", "30",
                                *client_args(router)], cwd=REPO, capture_output=True, text=True, timeout=60)
        assert watch.returncode == 0, watch
        lines = watch.stdout.splitlines()
        at = lines.index("violations (1)")
        assert lines[at + 1] == f"  {AG} at step 10 by manipulator:arm_ready.start#{seqs[9]}", watch.stdout
        at = lines.index("divergences and manager restarts (1)")
        assert re.fullmatch(rf"  violation at step 10 \(\d\d:\d\d:\d\d\): manipulator:arm_ready\.start#{seqs[9]}: "
                            rf"{AG} is violated from this step", lines[at + 1]), watch.stdout
    finally:
        monitor.close()

"""The monitor service over real Zenoh sessions on loopback (docs/semantics.md §1, §5, §7).

A Python router-mode session (``router`` fixture) links client sessions; the
predictor, the monitor process, ``skinet run`` and ``skinet router`` run as
separate processes where process boundaries matter (kill, restart, signals).
Every wait has a deadline; nothing relies on a blind sleep.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import msgpack
import pytest
import zenoh

from services.monitor import Monitor, start_monitor
from services.predictor.service import start_predictor
from skinet.system.load import load_system
from skinet.system.live import LiveSystem
from skinet.system.model import System
from skinet.verify.algorithm1 import analyse
from skinet.verify.predict import forecast
from skinet.wire import keys
from skinet.wire.codec import decode, encode
from skinet.wire.messages import (
    CanonicalEvent, LiveState, PredictRequest, StateSpaceReport, UnsafeReport, Verdicts,
)
from tests.bridge_side import BridgeSide as Events  # noqa: F401  (imported from here by other tests)
from tests.processes import run_skinet, start_module, start_skinet, stop
from tests.services.conftest import LivelinessWatch, client_args, free_port, open_client

REPO = Path(__file__).resolve().parents[2]
SYSTEM_FILE = REPO / "skillsets" / "spot_arm.toml"
AG, SG = "action_guard", "safety_guard"
TOPICS = {"state": LiveState, "verdicts": Verdicts, "unsafe": UnsafeReport, "state_space": StateSpaceReport}


# -- helpers ------------------------------------------------------------------------------


class Reports:
    """Everything published under ``skinet/<system>/`` for the monitor, in arrival order."""

    def __init__(self, session: zenoh.Session, system: str = "spot_arm"):
        self.items: list[tuple[str, float, Any]] = []
        self._cond = threading.Condition()
        self._subs = [session.declare_subscriber(getattr(keys, topic)(system), self._callback(topic, kind))
                      for topic, kind in TOPICS.items()]

    def _callback(self, topic: str, kind: type) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            msg = decode(sample.payload.to_bytes(), kind)
            with self._cond:
                self.items.append((topic, time.perf_counter(), msg))
                self._cond.notify_all()
        return on_sample

    def wait(self, topic: str, predicate: Callable[[Any], bool] = lambda m: True, timeout: float = 5.0,
             after: int = 0) -> Any:
        """The first ``topic`` message (from index ``after``) satisfying ``predicate``."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for t, _, msg in self.items[after:]:
                    if t == topic and predicate(msg):
                        return msg
                left = deadline - time.monotonic()
                if left <= 0:
                    seen = [(t, getattr(m, "seq", None)) for t, _, m in self.items[-10:]]
                    pytest.fail(f"no matching {topic} within {timeout} s; last seen {seen}")
                self._cond.wait(left)

    def step(self, seq: int, timeout: float = 5.0) -> tuple[LiveState, Verdicts, UnsafeReport]:
        """The three messages of monitor step ``seq`` (the UnsafeReport first published for it)."""
        return (self.wait("state", lambda m: m.seq == seq, timeout), self.wait("verdicts", lambda m: m.seq == seq, timeout),
                self.wait("unsafe", lambda m: m.seq == seq, timeout))

    def arrival(self, topic: str, predicate: Callable[[Any], bool]) -> float:
        with self._cond:
            return next(t0 for t, t0, m in self.items if t == topic and predicate(m))


def wait_until(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f"{what}: not within {timeout} s")
        time.sleep(0.01)


def entries(report: UnsafeReport) -> list[tuple]:
    return sorted((e.skillset, e.transition, e.property, e.constraint, e.controllable) for e in report.unsafe)


@pytest.fixture(scope="module")
def system() -> System:
    return load_system(SYSTEM_FILE)[0]


@pytest.fixture
def session(router: str) -> Iterator[zenoh.Session]:
    """The test's own client session (events in, reports out)."""
    s = open_client(router)
    yield s
    s.close()


@pytest.fixture
def monitor_factory(router: str, session: zenoh.Session) -> Iterator[Callable[..., Monitor]]:
    """Starts monitors on their own client session and waits until they listen."""
    started: list[tuple[Monitor, zenoh.Session]] = []
    watch = LivelinessWatch(session, keys.alive("*", "monitor", "*"))

    def start(sys_: System, **options: Any) -> Monitor:
        s = open_client(router)
        m = start_monitor(s, sys_, **options)
        started.append((m, s))
        token = keys.alive(sys_.name, "monitor", m.instance_id)
        watch.wait(lambda alive: token in alive)
        return m

    yield start
    watch.close()
    for m, s in started:
        m.close()
        s.close()


# -- (a) the paper's warnings and one violation ------------------------------------------

# Events of both paper runs (docs/mission.md) and the exact operator view after each.
WARN_GTW = [("spot", "go_to_waypoint.start", SG, "explicit", True)]  # before trap 2's transfer
WARN_ARM = [("manipulator", "arm_ready.start", AG, "explicit", True)]  # trap 3: teleop still runs
ARM_BUSY = sorted([("spot", "sit_down.start", AG, "explicit", True), ("spot", "go_to_waypoint.start", AG, "explicit", True),
                   ("spot", "go_to_waypoint.start", SG, "explicit", True), ("spot", "teleop.start", AG, "explicit", True)])
# After which action_guard holds again: at least stopping either movement (the rest,
# such as outcomes and emergency events, depends on the model and is checked against the core).
RECOVERY_AG = {("spot", "teleop.interrupt", True), ("manipulator", "arm_ready.interrupt", True),
               ("spot", "teleop.success.done", False), ("manipulator", "arm_ready.success.ready", False)}
PAPER_STEPS: list[tuple[str, str, list[tuple], list[str]]] = [
    ("spot", "init_power.start", WARN_ARM, []),
    ("spot", "init_power.success.powered_on", [], []),
    ("spot", "stand_up.start", WARN_ARM, []),
    ("spot", "stand_up.success.standing", [], []),
    ("manipulator", "arm_ready.start", ARM_BUSY, []),
    ("manipulator", "arm_ready.success.ready", WARN_GTW, []),  # paper warning 1
    ("manipulator", "arm_RD_to_HP.start", ARM_BUSY, []),
    ("manipulator", "arm_RD_to_HP.success.at_home", [], []),
    ("spot", "teleop.start", WARN_ARM, []),  # paper warning 2
    ("manipulator", "arm_ready.start", [], [AG]),  # warning ignored: violation
    ("spot", "teleop.success.done", ARM_BUSY, []),  # recovered
]


def test_paper_sequence_exact_reports(monitor_factory, session, system):
    reports = Reports(session)
    monitor_factory(system)
    events = Events(session)
    live = LiveSystem(system)
    for step, (skillset, transition, unsafe, violated) in enumerate(PAPER_STEPS, 1):
        seq = events.send(skillset, transition)
        state, verdicts, report = reports.step(step)
        live.apply(skillset, transition)
        core = analyse(system, live.marking)
        assert state.event == f"{skillset}:{transition}#{seq}" and state.divergence is None
        assert entries(report) == sorted(unsafe), transition
        assert report.prediction_stale is True  # no predictor here
        assert report.violated == violated
        assert {v.name: v.holds for v in verdicts.properties} == {AG: AG not in violated, SG: True}
        assert all(e.kind == "start" and e.steps == 0 and e.witness == [] for e in report.unsafe)
        assert report.literal_count == len(core.unsafe)
        recovery = [(r.property, r.skillset, r.transition, r.controllable) for r in report.recovery]
        assert recovery == [(p, r.skillset, r.transition, r.controllable) for p, rs in core.recovery.items() for r in rs]
        if violated:
            assert RECOVERY_AG <= {r[1:] for r in recovery} and {r[0] for r in recovery} == {AG}
        else:
            assert recovery == [] and report.literal_count == len(unsafe)
    assert state.skillsets["spot"].resources["control_mode"] == "Idle"
    assert state.skillsets["manipulator"].running == ["arm_ready"]


# -- (b) with a predictor -----------------------------------------------------------------


def _expect_prediction(reports: Reports, system: System, events: Events, steps: int) -> None:
    """Play the first ``steps`` paper events; the last step's report must turn fresh and match the core."""
    live = LiveSystem(system)
    for skillset, transition, _, _ in PAPER_STEPS[:steps]:
        events.send(skillset, transition)
        live.apply(skillset, transition)
    fresh = reports.wait("unsafe", lambda m: m.seq == steps and not m.prediction_stale, timeout=10)
    expected = forecast(system, live.marking, budget=5.0)
    space = reports.wait("state_space", lambda m: m.markings == expected.space.markings, timeout=5)
    assert not space.timeout_reached and space.system == system.name
    core = analyse(system, live.marking, expected).operator_unsafe()
    assert entries(fresh) == sorted((u.skillset, u.transition, u.property, u.constraint, u.controllable) for u in core)
    assert [(e.steps, e.witness) for e in sorted(fresh.unsafe, key=lambda e: (e.skillset, e.transition, e.property))] == [
        (u.steps, list(u.witness)) for u in sorted(core, key=lambda u: (u.skillset, u.transition, u.property))]


def test_an_undecided_prediction_is_asked_again_until_a_predictor_decides_it(router, monitor_factory, session,
                                                                            system):
    """A prediction cut by the predictor's memory limit stays honest ("could not decide") and is asked again while
    its marking stays live (on a timer, and when a predictor appears): once a predictor with room answers, the
    same step's report turns complete, with no new event.  Before, the undecided answer was kept for its marking
    and a drive goal waited for ever."""
    reports = Reports(session)
    small_session = open_client(router)
    small = start_predictor(small_session, "small", memory_limit=1)  # every exploration cut at once
    big_session = open_client(router)
    try:
        monitor = monitor_factory(system, budget=5.0)  # room for a loaded machine: only the memory limit cuts
        cut = reports.wait("state_space", lambda m: m.timeout_reached, timeout=30)
        assert cut.markings < 10
        after = len(reports.items)
        start_predictor(big_session, "big")  # its workers start while the small one still answers
        wait_until(lambda: "big" in monitor.predictor_stats.instances, 20, "the big predictor in the pool")
        small.close()
        space = reports.wait("state_space", lambda m: not m.timeout_reached, timeout=60, after=after)
        assert space.markings == forecast(system, system.initial_marking(), budget=5.0).space.markings
        fresh = reports.wait("unsafe", lambda m: not m.prediction_stale, timeout=5, after=after)
        assert (fresh.seq, monitor.predictor_stats.last_instance) == (0, "big")
        assert {m.seq for t, _, m in reports.items if t == "state"} == {0}, "no new step: the same marking"
    finally:
        small_session.close()
        big_session.close()


def test_an_undecided_prediction_is_asked_again_five_times_then_left_undecided(router, monitor_factory, session,
                                                                            system, monkeypatch):
    """The re-asks back off (REASK_FIRST x 1, 2, 4, 8, 16) and stop after five: a predictor too small for a
    system is not asked for ever; the answer stays undecided.  One marking (no event): six answers in all."""
    import services.monitor.service as monitor_service

    monkeypatch.setattr(monitor_service, "REASK_FIRST", 0.05)
    reports = Reports(session)
    small_session = open_client(router)
    start_predictor(small_session, "small", memory_limit=1)
    try:
        monitor = monitor_factory(system, budget=5.0)
        wait_until(lambda: monitor.reasked == 5 and monitor.predictor_stats.answered == 6, 60, "five re-asks")
        time.sleep(2.0)  # a sixth would have come 1.6 s after the first at the latest: none
        stats = monitor.predictor_stats
        assert (monitor.reasked, stats.answered, stats.answers, stats.last_complete) == (5, 6, {"small": 6}, False)
        spaces = [m for t, _, m in reports.items if t == "state_space"]
        assert len(spaces) == 6 and all(m.timeout_reached for m in spaces)
    finally:
        small_session.close()


def test_prediction_in_process(router, monitor_factory, session, system):
    reports = Reports(session)
    psession = open_client(router)
    predictor = start_predictor(psession, "inproc")
    try:
        monitor = monitor_factory(system)
        _expect_prediction(reports, system, Events(session), 6)
        stats = monitor.predictor_stats
        assert stats.answered >= 1 and stats.last_instance == "inproc" and stats.last_complete
    finally:
        predictor.close()
        psession.close()


def test_big_system_answered_within_the_budget_never_a_timeout(router, monitor_factory, session, tmp_path):
    """4 + 4 skillsets (docs/semantics.md §6.1): the predictor answers within its budget; the derived query timeout holds."""
    fleet = load_system(_heavy_system(tmp_path))[0]
    psession = open_client(router)
    predictor = start_predictor(psession, "big")
    try:
        monitor = monitor_factory(fleet, budget=1.0)  # default query timeout: derived from the budget
        wait_until(lambda: monitor.predictor_stats.answered >= 1, 20, "first prediction")
        stats = monitor.predictor_stats
        # The query never times out: its timeout covers the budget and the predictor's grace.  A worker killed
        # at budget + grace is the predictor's honest failure, asked again (seen once beside busy loops on both
        # cores).
        assert stats.timed_out == 0 and stats.unanswered == 0 and stats.last_instance == "big", stats
        assert stats.last_complete is False  # truncated, yet answered
        assert not monitor.snapshot().unsafe.prediction_stale
    finally:
        predictor.close()
        psession.close()


def test_prediction_from_predictor_process(router, monitor_factory, session, system, tmp_path):
    reports = Reports(session)
    watch = LivelinessWatch(session, keys.alive("*", "predictor", "*"))
    proc = start_module("services.predictor", *client_args(router), "--instance", "proc1",
                        log=tmp_path / "predictor.log")
    try:
        watch.wait(lambda alive: keys.alive(keys.ANY_SYSTEM, "predictor", "proc1") in alive)
        monitor = monitor_factory(system)
        _expect_prediction(reports, system, Events(session), 9)
        assert monitor.predictor_stats.last_instance == "proc1"
    finally:
        assert stop(proc) == 0, (tmp_path / "predictor.log").read_text()
        watch.close()


# -- (c) without predictor, and with one that never answers -------------------------------


def test_no_predictor_reports_stay_on_time(monitor_factory, session, system):
    reports = Reports(session)
    monitor = monitor_factory(system, retry=0.2)
    events = Events(session)
    for step, (skillset, transition, unsafe, _) in enumerate(PAPER_STEPS, 1):
        sent = time.perf_counter()
        events.send(skillset, transition)
        _, _, report = reports.step(step)
        assert report.prediction_stale and entries(report) == sorted(unsafe)
        # On time: nothing waits for a predictor (bound generous for loaded CI machines).
        assert reports.arrival("unsafe", lambda m, s=step: m.seq == s) - sent < 0.5
        time.sleep(0.05)  # a robot's pace: lets retries happen between events
    stats = monitor.predictor_stats
    assert stats.answered == 0 and stats.unanswered >= 1 and stats.sent == stats.unanswered + stats.in_flight
    assert stats.sent <= 10  # retries are paced, not one per event burst


def test_silent_predictor_times_out_without_blocking(monitor_factory, session, system):
    held: list[zenoh.Query] = []
    silent = session.declare_queryable(keys.predict("*", "*"), held.append)  # never replies (ZENOH.md: holds the get)
    reports = Reports(session)
    monitor = monitor_factory(system, budget=0.3, query_timeout=3.0)
    wait_until(lambda: monitor.predictor_stats.in_flight, 5, "query in flight")
    events = Events(session)
    for step, (skillset, transition, unsafe, _) in enumerate(PAPER_STEPS[:4], 1):
        sent = time.perf_counter()
        events.send(skillset, transition)
        _, _, report = reports.step(step)
        assert report.prediction_stale and entries(report) == sorted(unsafe)
        assert reports.arrival("unsafe", lambda m, s=step: m.seq == s) - sent < 1.0  # not after the 3 s timeout
    assert monitor.predictor_stats.in_flight  # the events came and went while the query hung
    wait_until(lambda: monitor.predictor_stats.timed_out >= 1, 6, "timeout counted")
    request = decode(held[0].payload.to_bytes(), PredictRequest)
    assert request.budget == 0.3 and request.digest == monitor.digest and request.system == "spot_arm"
    assert monitor.predictor_stats.answered == 0
    silent.undeclare()
    held.clear()


# -- (d) predictor killed mid-query and restarted -----------------------------------------


def _heavy_system(folder: Path, pairs: int = 4) -> Path:
    """Four Spots and four arms (three: fewer); the predictor uses the whole budget on it (docs/semantics.md §6.1)."""
    spot = (REPO / "skillsets" / "spot.rl").read_text()
    arm = (REPO / "skillsets" / "manipulator.rl").read_text()
    lines = ['[system]\nname = "fleet"\nproperties = "fleet.props"\n']
    props = []
    for i in range(1, pairs + 1):
        (folder / f"spot{i}.rl").write_text(spot.replace("skillset spot {", f"skillset spot{i} {{"))
        (folder / f"arm{i}.rl").write_text(arm.replace("skillset manipulator {", f"skillset arm{i} {{"))
        lines += [f'[[skillsets]]\nmodel = "spot{i}.rl"\n', f'[[skillsets]]\nmodel = "arm{i}.rl"\n']
        props.append(f"guard{i} = not (spot{i}:Busy and arm{i}:Busy)\n")
    (folder / "fleet.props").write_text("".join(props))
    (folder / "fleet.toml").write_text("".join(lines))
    return folder / "fleet.toml"


def test_predictor_killed_mid_query_then_restarted(router, monitor_factory, session, tmp_path):
    fleet = load_system(_heavy_system(tmp_path))[0]
    reports = Reports(session, "fleet")
    watch = LivelinessWatch(session, keys.alive("*", "predictor", "*"))
    # A long grace: this test is about a predictor dying, not about the worker killed at
    # budget + grace (tests/services/test_hostile.py), and exploring this system may
    # outlast a small budget and take over a gigabyte.
    args = ["services.predictor", *client_args(router), "--grace", "60", "--memory-mb", "4096", "--instance"]
    first = start_module(*args, "doomed", log=tmp_path / "doomed.log")
    try:
        watch.wait(lambda alive: any(a.endswith("/doomed") for a in alive))
        monitor = monitor_factory(fleet, budget=5.0, query_timeout=30.0, retry=30.0)  # killed within the budget
        wait_until(lambda: monitor.predictor_stats.in_flight, 5, "query sent")
        wait_until(lambda: "fetched model" in (tmp_path / "doomed.log").read_text(), 5, "exploration started")
        assert monitor.predictor_stats.answered == 0, "exploration finished before the kill"
        killed = time.monotonic()
        first.send_signal(signal.SIGKILL)
        wait_until(lambda: not monitor.predictor_stats.in_flight, 5, "query returns after the kill")
        assert time.monotonic() - killed < 3.0  # at once, not after the 30 s timeout
        stats = monitor.predictor_stats
        assert stats.answered == 0 and stats.timed_out == 0 and stats.unanswered + stats.failed == 1
        watch.wait(lambda alive: not any(a.endswith("/doomed") for a in alive))
    finally:
        stop(first, signal.SIGKILL)
    second = start_module(*args, "phoenix", log=tmp_path / "phoenix.log")
    try:  # its liveliness token lifts the 30 s retry delay
        fresh = reports.wait("unsafe", lambda m: not m.prediction_stale, timeout=15)
        assert fresh.seq == 0 and monitor.predictor_stats.last_instance == "phoenix"
        reports.wait("state_space", lambda m: m.system == "fleet", timeout=2)
    finally:
        stop(second)
        watch.close()


# -- (e) garbage, (f) duplicates and order, (g) divergence --------------------------------


def test_garbage_is_counted_and_later_events_processed(monitor_factory, session, system):
    reports = Reports(session)
    monitor = monitor_factory(system)
    events = Events(session)
    good = CanonicalEvent(system="spot_arm", skillset="spot", seq=0, stamp=0.0, transition="init_power.start")
    junk = [
        b"", b"\xc1\xff garbage", msgpack.packb([1, 2, 3]), msgpack.packb({"v": 2, "system": "spot_arm"}),
        msgpack.packb({**good.model_dump(mode="json"), "seq": -1}),
        msgpack.packb({**good.model_dump(mode="json"), "extra": 1}),
        encode(PredictRequest(system="spot_arm", digest="x", seq=0, skillsets={})),
        encode(good.model_copy(update={"system": "other"})),
        os.urandom(512),
    ]
    for payload in junk:
        events.raw("spot", payload)
    events.send("spot", "init_power.start")
    _, _, report = reports.step(1)
    assert entries(report) == sorted(WARN_ARM)
    c = monitor.counters
    assert (c.received, c.malformed, c.applied, c.errors) == (len(junk) + 1, len(junk), 1, 0)


def test_the_tap_gets_each_steps_messages_then_its_event_and_cannot_cost_one(monitor_factory, session, system,
                                                                          caplog):
    """``tap`` (--incidents' ring) is handed the step's three messages once published, then the event with the
    earlier time it came; a tap that raises is logged and the monitor goes on with every event."""
    handed: list[tuple[str, bytes, float]] = []

    def tap(key: str, payload: bytes, t: float) -> None:
        handed.append((key, payload, t))
        raise RuntimeError("a broken ring")

    reports = Reports(session)
    monitor = monitor_factory(system, tap=tap)
    events = Events(session)
    events.send("spot", "init_power.start")
    events.send("spot", "init_power.success.powered_on")
    reports.step(2)
    assert monitor.counters.applied == 2 and monitor.counters.errors == 0
    wait_until(lambda: sum(k.endswith("/events/spot") for k, _, _ in handed) == 2, 10, "both events tapped")
    step_keys = ["skinet/spot_arm/state", "skinet/spot_arm/verdicts", "skinet/spot_arm/unsafe"]
    # Handed: each event just after its step's messages; in time order, just before them.
    handed_keys = [k for k, _, _ in handed]
    at = [i for i, k in enumerate(handed_keys) if k.endswith("/events/spot")]
    assert [handed_keys[i - 3:i] for i in at] == [step_keys, step_keys]
    timed = sorted(handed, key=lambda h: h[2])
    at = [i for i, (k, _, _) in enumerate(timed) if k.endswith("/events/spot")]
    assert [decode(timed[i][1], CanonicalEvent).transition for i in at] == \
        ["init_power.start", "init_power.success.powered_on"]
    for step, i in enumerate(at, 1):
        assert [k for k, _, _ in timed[i + 1:i + 4]] == step_keys
        assert decode(timed[i + 3][1], UnsafeReport).seq == step
    assert caplog.text.count("error in the monitor's tap (--incidents, --foxglove)") >= 8


def test_duplicates_and_out_of_order_are_not_applied_twice(monitor_factory, session, system):
    reports = Reports(session)
    monitor = monitor_factory(system)
    events = Events(session)
    # Synced at #0 (the initial status): the streams go on from #1.
    events.send("spot", "init_power.start", seq=1)
    events.send("spot", "init_power.success.powered_on", seq=2)
    events.send("spot", "init_power.success.powered_on", seq=2)  # duplicate
    events.send("spot", "init_power.start", seq=1)  # older
    events.send("spot", "stand_up.start", seq=4)  # seq 3 lost
    events.send("spot", "stand_up.success.standing", seq=3)  # late: older than 4
    events.send("manipulator", "arm_ready.start", seq=1)
    state, _, report = reports.step(4)
    wait_until(lambda: monitor.counters.received == 7, 5, "all events received")
    c = monitor.counters
    # The late #3 is out of order, or history when the resync that #4's gap asked for answered first (#4's status
    # then covers it: a busy run saw it); applied in neither case.
    assert (c.applied, c.duplicates, c.out_of_order + c.history, c.lost, c.divergences) == (4, 1, 2, 1, 0)
    assert c.out_of_order >= 1  # the older #1 came before any resync
    assert state.event == "manipulator:arm_ready.start#1" and state.divergence is None
    assert state.skillsets["spot"].running == ["stand_up"] and report.violated == [AG]
    assert monitor.snapshot().state.seq == 4  # the ignored events published nothing


def test_divergence_is_reported_and_observed_marking_adopted(monitor_factory, session, system):
    reports = Reports(session)
    monitor = monitor_factory(system)
    events = Events(session)
    standing = {"resources": {"power_status": "PowerOn", "posture": "Standing", "control_mode": "Idle"}, "running": []}
    events.send("spot", None, status=standing)  # no single transition gets there from the initial marking
    state, verdicts, report = reports.step(1)
    assert state.divergence and "no transition explains" in state.divergence and "adopted" in state.divergence
    assert state.skillsets["spot"].model_dump() == standing
    assert entries(report) == []  # Algorithm 1 runs on the adopted marking (arm at home: nothing unsafe)
    events.send("spot", "teleop.start", status={**standing, "running": ["teleop"],
                                                "resources": {**standing["resources"], "control_mode": "Busy"}})
    state, _, _ = reports.step(2)
    assert state.divergence is None and state.skillsets["spot"].running == ["teleop"]
    events.send("manipulator", "arm_RD_to_HP.start")  # not enabled: the arm is at home
    state, _, _ = reports.step(3)
    assert "not enabled" in state.divergence
    events.send("gripper", "open.start")  # unknown skillset
    state, _, _ = reports.step(4)
    assert "unknown skillset 'gripper'" in state.divergence
    assert monitor.counters.divergences == 3


# -- (h) processes: skinet run, skinet router, python -m services.monitor ----------------


def test_skinet_run_once_prints_the_view():
    out = subprocess.run([sys.executable, "-m", "skinet_cli.main", "run", str(SYSTEM_FILE), "--once",
                          "--no-multicast-scouting"], cwd=REPO, capture_output=True, text=True, timeout=20)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "SkiNet Live  system spot_arm  step 0" in text
    assert "spot         power_status=PowerOff posture=Sitting control_mode=Idle; running: -" in text
    assert "action_guard: holds" in text and "safety_guard: holds" in text
    assert "unsafe transitions (0), prediction fresh" in text
    assert "markings" in text and "complete" in text and "answered 1" in text


def test_skinet_run_listens_for_a_bridge_and_logs_changes(tmp_path):
    """... and with ``--incidents`` its monitor hands the run to the ring: the divergence's bundle holds its event
    and verifies."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    folder = tmp_path / "incidents"
    proc = start_skinet("run", str(SYSTEM_FILE), "--listen", endpoint, "--no-multicast-scouting", "--duration", "15",
                        "--incidents", str(folder), "--incident-window", "1")
    bridge = None
    try:
        assert proc.stdout is not None
        connect = [proc.stdout.readline() for _ in range(7)]  # issue 27: where it listens, what reaches it
        assert connect == [f"skinet run: system spot_arm, listening on {endpoint}; connect with:\n",
                           f"  skinet watch spot_arm -e {endpoint}\n", f"  skinet dashboard spot_arm -e {endpoint}\n",
                           f"  skinet check spot_arm spot:init_power.start -e {endpoint}\n",
                           f"  python -m services.bridge_ros2 {SYSTEM_FILE} -e {endpoint}   (the robot's side)\n",
                           "  pilot: goals on skinet/spot_arm/pilot/goal/<client> (<client>: your login, 'local' "
                           "without one), status on skinet/spot_arm/pilot/status\n",
                           f"  skinet goal spot_arm \"run spot:init_power\" -e {endpoint}   (guided; --drive: the pilot "
                           "sends the commands)\n"]
        assert proc.stdout.readline().startswith("[0] start")  # listening now
        bridge = open_client(endpoint)  # a bridge connects to the embedded peer
        watch = LivelinessWatch(bridge, keys.alive("spot_arm", "monitor", "*"))
        watch.wait(bool, timeout=10)
        events = Events(bridge)
        for skillset, transition, _, _ in PAPER_STEPS[:9]:
            events.send(skillset, transition)
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("[9] spot:teleop.start#"):
                break
        assert "unsafe: manipulator:arm_ready.start(action_guard explicit)" in lines[-1]
        # A model divergence: its step's line says so, and a line of its own lists it (issue 27 item 4).
        events.send("spot", "init_power.success.powered_on")
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("MODEL DIVERGENCE"):
                break
        assert re.fullmatch(r"MODEL DIVERGENCE at step 10 \(\d\d:\d\d:\d\d\): spot:init_power.success.powered_on#\d+: "
                            r"'init_power.success.powered_on' is not enabled in the live marking\n", lines[-1]), lines
        assert lines[-2].startswith("[10] spot:init_power.success.powered_on#") and " DIVERGENCE: " in lines[-2]
        watch.close()
        wait_until(lambda: any(p.suffix == ".mcap" and not p.name.startswith(".") for p in folder.iterdir()), 30,
                   "the divergence's incident bundle")
    finally:
        if bridge is not None:
            bridge.close()
        assert stop(proc, signal.SIGINT) == 0
    from mcap.reader import make_reader

    [path] = list(folder.iterdir())
    with path.open("rb") as f:
        reader = make_reader(f)
        trigger = {m.name: m.metadata for m in reader.iter_metadata()}["skinet"]["trigger"]
        topics = [channel.topic for _, channel, _ in reader.iter_messages()]
    assert trigger == "model divergence" and "/skinet/divergences" in topics
    done = run_skinet("replay", str(path), "--verify")
    assert (done.returncode, done.stdout) == (0, "0 differences\n"), done.stderr


def test_skinet_router_links_clients():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = start_skinet("router", "--listen", endpoint, "--no-auth", "--no-multicast-scouting")
    try:
        assert proc.stdout is not None and "listening on " + endpoint in proc.stdout.readline()
        a, b = open_client(endpoint), open_client(endpoint)
        got = threading.Event()
        sub = b.declare_subscriber("skinet/test/ping", lambda s: got.set())
        token = b.liveliness().declare_token("skinet/test/alive/x/y")
        watch = LivelinessWatch(a, "skinet/test/alive/**")
        watch.wait(bool)  # b's subscriber is declared before its token
        a.put("skinet/test/ping", b"1")
        assert got.wait(5)
        watch.close()
        token.undeclare()
        sub.undeclare()
        a.close()
        b.close()
    finally:
        assert stop(proc, signal.SIGTERM) == 0


def test_monitor_process_serves_and_stops_cleanly(router, session, tmp_path):
    reports = Reports(session)
    watch = LivelinessWatch(session, keys.alive("spot_arm", "monitor", "*"))
    log = tmp_path / "monitor.log"
    proc = start_module("services.monitor", str(SYSTEM_FILE), *client_args(router), "--id", "m1", log=log)
    try:
        watch.wait(lambda alive: keys.alive("spot_arm", "monitor", "m1") in alive)
        model = [r for r in session.get(keys.model("spot_arm"), timeout=5) if r.ok is not None]
        assert len(model) == 1 and str(model[0].ok.key_expr).startswith("skinet/spot_arm/model/")
        events = Events(session)
        for skillset, transition, _, _ in PAPER_STEPS[:6]:
            events.send(skillset, transition)
        _, _, report = reports.step(6)
        assert entries(report) == sorted(WARN_GTW)
    finally:
        assert stop(proc, signal.SIGTERM) == 0, log.read_text()
        watch.close()
    assert "stopped: 6 received, 6 applied" in log.read_text()
